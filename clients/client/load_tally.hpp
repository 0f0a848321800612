// load_tally.hpp — what `mocap-client load` counts per client, for both transports (the pose
// service's sockets, load_client.cpp, and a NATS cluster, nats_load_client.cpp): frames,
// SYNC jumps beyond the decimation (gaps), and the latency from a frame's sink_send_us to
// the moment it was read (CLOCK_REALTIME µs; meaningful when sink and client share a clock).
// One ClientTally is touched by one thread at a time; merge_tallies() runs after the readers
// stopped.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "load_client.hpp"
#include "mocap/v1/mocap.pb.h"

namespace mocap::client {

/// Latencies kept for exact percentiles, over all clients; beyond this, further samples are
/// counted but not stored (20 M samples = 1000 clients x 100 Hz x 200 s; 80 MB).
constexpr std::size_t kMaxLatencySamples = 20'000'000;

struct ClientTally {
    std::uint64_t frames = 0;
    std::uint64_t gaps = 0;
    std::uint64_t missing_frames = 0;
    std::uint64_t latency_samples = 0;
    std::uint64_t negative_latencies = 0;
    std::vector<std::int32_t> latencies_us;                          // at most `max_latencies`
    std::vector<std::pair<std::uint32_t, std::uint64_t>> last_sync;  // per subject

    /// One received frame, read at `receive_us`.
    void add(const v1::SkeletonFrame& frame, std::int64_t receive_us, std::uint32_t decimation,
             std::size_t max_latencies);
};

/// Sums the tallies of the clients that were subscribed (`counted[i]`) into `result`: frames,
/// per-client minimum and maximum, gaps, latency samples and exact percentiles.
void merge_tallies(std::vector<ClientTally>& tallies, const std::vector<bool>& counted, LoadResult& result);

}  // namespace mocap::client
