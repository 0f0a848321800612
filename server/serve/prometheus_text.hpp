// prometheus_text.hpp — mocapd's counters, gauges and stage latencies in the Prometheus
// text exposition format 0.0.4 (what GET /metrics returns).
//
// Naming (https://prometheus.io/docs/practices/naming/), applied to every name:
// - every metric is `mocapd_<component>_<name>`, lower case, [a-z0-9_] only;
// - a counter "component.name" becomes `mocapd_component_name_total`; a unit in the
//   name moves to the end as a base unit: "bytes_sent" -> `..._sent_bytes_total`,
//   "stall_us" -> `..._stall_seconds_total` (value scaled to seconds);
// - counters that map to the same name are summed into one series;
// - stage latencies form ONE histogram `mocapd_stage_latency_seconds{stage="..."}`
//   with fixed buckets (kLatencyBucketsS). Its `le` counts are read off the daemon's
//   log-linear µs histogram: a fine bucket counts toward `le` when its upper bound is
//   <= le, so a value up to 1/32 below a bound may land in the next bound (never an
//   earlier one); _sum and _count are exact.
// Every family has # HELP and # TYPE lines. The snapshot is the metrics registry's
// (core/metrics_registry.hpp): /metrics is one of its three renderers, with the Stats reply
// and the log line. Thread-safety: pure functions.
// Cost: a few µs per metric (stats path only, never the hot path).
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "core/metrics_registry.hpp"

namespace mocap::serve {

using mocap::MetricsSnapshot;  // the registry's snapshot; serve::MetricsSnapshot is the same type

/// Upper bounds (seconds) of the latency histogram's buckets; +Inf is added.
inline constexpr std::array<double, 16> kLatencyBucketsS{0.00005, 0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01,
                                                         0.025,   0.05,   0.1,     0.25,   0.5,   1.0,    2.5,   10.0};

/// Prometheus name of counter "component.name" (with the _total suffix); *divisor is
/// set to what its value is divided by to be in the named unit (1, 1e3 for ms, 1e6 for µs).
std::string prometheus_counter_name(std::string_view dotted, double* divisor);

/// Renders the snapshot (text format 0.0.4, '\n' line ends, ends with '\n').
std::string render_prometheus(const MetricsSnapshot& snapshot);

}  // namespace mocap::serve
