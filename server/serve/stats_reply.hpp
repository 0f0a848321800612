// stats_reply.hpp — the pose service's Stats reply (protobuf), rendered from a
// MetricsSnapshot (core/metrics_registry.hpp).
//
// Every counter keeps its registry name ("component.name"); every stage latency becomes a
// StageLatency with its count, p50/p90/p99 (bucket upper bounds, at most 1/32 above the true
// value; core/latency_histogram.hpp) and exact max. Gauges have no field in Stats and are not
// rendered (they are in /metrics). Pure function; allocates.
#pragma once

#include "core/metrics_registry.hpp"

namespace mocap::v1 {
class Stats;
}

namespace mocap::serve {

/// Appends the snapshot's counters and latencies to `out` (request id and time untouched).
void render_stats(const MetricsSnapshot& snapshot, v1::Stats& out);

}  // namespace mocap::serve
