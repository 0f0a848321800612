// control_access.hpp — who may send control requests (calibrate, record, reload), shared
// by the pose service (ClientSession) and HTTP (POST /api/...), so both apply the same
// rules in the same order and count refusals the same way (docs/security.md):
//
//   1. no token configured          -> refused ("control disabled (no token configured)")
//   2. loopback_only and the peer is not on loopback (IPv4 127/8, ::1, or ::ffff:127.x)
//                                   -> refused ("control only from loopback")
//   3. no token given               -> refused ("token required")
//   4. token differs (compared in constant time) -> refused ("bad token")
//
// The address rule comes before the token check so a remote peer learns nothing about
// the token. Counters only go up (docs/style.md, "Counters only go up"); each owner exposes
// them under its own prefix (serve.control_*, http.control_*), names that dashboards
// depend on.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/asio.hpp"
#include "core/counters.hpp"
#include "serve/serve_config.hpp"

namespace mocap::serve {

class LogLimiter;

/// Constant-time token comparison (time depends only on the longer length).
bool token_equal(std::string_view expected, std::string_view given);

/// True for IPv4 and IPv6 loopback, including IPv4 loopback mapped into IPv6.
bool is_loopback(const asio::ip::address& address);

/// The connected peer is on loopback; false when the peer is unknown (socket closed).
bool peer_on_loopback(const asio::ip::tcp::socket& socket);

struct ControlCounters {
    Counter ok;
    Counter failed;            ///< authorised, but the action reported an error
    Counter refused_disabled;  ///< no token configured
    Counter refused_not_loopback;
    Counter refused_no_token;
    Counter refused_bad_token;

    /// Set-up: adds every counter to the server's group as "control_<name>".
    void register_in(CounterGroup& group) const;
    /// Counts an authorised request's outcome in ok or failed.
    void count_result(const ControlResult& result);
};

struct ControlPolicy {
    std::string_view token;  ///< empty = every control request is refused
    bool loopback_only = true;
};

struct ControlRefusal {
    enum Kind { kDisabled, kNotLoopback, kNoToken, kBadToken } kind;
    const char* reason;  ///< shown to the client
};

/// Applies the rules above. nullopt = authorised; otherwise the refusal, already counted
/// and logged through `log` as "<who> refused: <reason>", one line per interval (`who`
/// e.g. "http: control request /api/calibrate"; tests count those lines).
std::optional<ControlRefusal> authorize_control(const ControlPolicy& policy, bool peer_loopback,
                                                std::string_view given_token, ControlCounters& counters,
                                                LogLimiter& log, std::string_view who);

}  // namespace mocap::serve
