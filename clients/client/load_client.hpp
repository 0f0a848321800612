// load_client.hpp — `mocap-client load`: N subscriptions on N sockets, counted.
//
// Opens `clients` connections (each waits for its Hello), subscribes them all, then
// reads every socket through one epoll loop for `duration`. Per frame it records the
// latency from the frame's sink_send_us to the moment its bytes were read here
// (CLOCK_REALTIME µs; meaningful when sink and client share a clock, e.g. loopback),
// and per client and subject the SYNC jumps larger than the decimation (gaps).
// Frames the server dropped for a client arrive as DropNotices and are summed.
// Bounded: connecting is bounded by connect_timeout per client, the loop by duration.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace mocap::client {

struct LoadOptions {
    std::string host = "127.0.0.1";
    std::uint16_t port = 7001;
    /// "pose" (the protobuf stream), "bvh" (live BVH text) or "ws" (the viewer WebSocket);
    /// the last two: load_stream_client.hpp.
    std::string protocol = "pose";
    std::size_t clients = 10;
    std::chrono::milliseconds duration{5000};
    std::vector<std::uint32_t> subject_ids;  ///< empty = all
    std::uint32_t decimation = 1;
    std::uint32_t fields = 0;
    std::chrono::milliseconds connect_timeout{3000};
    /// Extra connections that subscribe like the others and then never read (they test
    /// that a stalled client does not slow the measured ones); not measured themselves.
    std::size_t stalled = 0;
    /// Extra connections that keep re-sending Subscribe naming `churn_subjects` subject ids
    /// (the subscription-churn attack of issue 13, item 1), `churn_pipelined` at a time, from
    /// a thread of their own; not measured. A churner the server closes connects again.
    std::size_t churn_clients = 0;
    std::uint32_t churn_subjects = 4096;
    std::uint32_t churn_pipelined = 8;
};

struct LoadResult {
    std::size_t clients = 0;       ///< requested
    std::size_t stalled = 0;       ///< never-reading connections that were subscribed
    std::size_t connected = 0;     ///< subscribed successfully
    std::size_t closed_early = 0;  ///< connections the server closed during the run
    double duration_s = 0;         ///< measured length of the read loop
    std::uint64_t frames = 0;      ///< frames received, all clients
    std::uint64_t frames_per_client_min = 0;
    std::uint64_t frames_per_client_max = 0;
    std::uint64_t gaps = 0;            ///< SYNC jumps beyond the decimation
    std::uint64_t missing_frames = 0;  ///< frames those jumps skipped
    std::uint64_t drops = 0;           ///< frames the server announced as dropped
    std::uint64_t latency_samples = 0;
    std::uint64_t negative_latencies = 0;                  ///< receive before send: clocks disagree
    std::optional<double> p50_ms, p90_ms, p99_ms, max_ms;  ///< empty without samples
    std::uint64_t churn_subscribes = 0;                    ///< Subscribed replies the churners received
    std::uint64_t churn_reconnects = 0;  ///< churner connections made again after the server closed one
    std::string error;                   ///< first connection error, if any
};

LoadResult run_load(const LoadOptions& options);

/// Raises RLIMIT_NOFILE towards its hard limit when `needed` descriptors would not fit.
void raise_fd_limit(std::size_t needed);

/// One JSON object (docs/design.md, "Command-line contracts": clients, frames, gaps, drops, p50_ms, p90_ms,
/// p99_ms, max_ms; plus the other LoadResult fields).
std::string load_result_json(const LoadResult& result);

}  // namespace mocap::client
