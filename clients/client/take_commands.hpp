// take_commands.hpp — `mocap-client takes ...`: the takes of a daemon over its web endpoint
// (docs/client-protocol.md, "Takes"; default --http 127.0.0.1:8080):
//
//   mocap-client takes list [--json]
//   mocap-client takes download NAME --format raw|bvh|csv [--filter F] [--offline] [--subject ID] [-o FILE]
//       raw: the recorded file; bvh/csv: re-solved by the daemon (with another filter when
//       given; --offline: the non-causal re-solve of mocapd --replay --offline). FILE defaults to NAME.mocapraw /
//       NAME.bvh / NAME.csv and must not exist; the body goes to FILE.part first and is renamed once complete, so FILE
//       is never partial.
//   mocap-client takes start [--name N] [--notes TEXT] | stop | delete NAME   (need the token)
//
// Blocking Beast HTTP/1.1, one connection per command, every socket call bounded by
// `timeout` (a BVH export of a long take needs a generous one). Exit codes as mocap-client:
// 0 done, 1 refused/failed (an HTTP error: its body is printed), 2 connection problem.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace mocap::client {

struct TakeCommand {
    std::string host = "127.0.0.1";
    std::uint16_t port = 8080;
    std::string token;  ///< start, stop, delete
    std::chrono::milliseconds timeout{120000};
    std::string action;  ///< list, download, start, stop, delete
    std::string name;
    std::string format = "raw";
    std::string filter;
    bool offline = false;
    std::uint32_t subject = 0;  ///< 0 = not sent (the daemon's rule)
    std::string out;
    std::string notes;
    bool json = false;
};

int run_takes(const TakeCommand& command);

/// application/x-www-form-urlencoded escaping of a query value (unreserved characters kept).
std::string url_encode(const std::string& text);

}  // namespace mocap::client
