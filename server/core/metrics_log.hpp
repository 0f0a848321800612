// metrics_log.hpp — the periodic stats log line, rendered from a MetricsSnapshot
// (core/metrics_registry.hpp): the daemon logs "stats:" followed by this text.
//
// Format: " name=value" for every counter that is not zero (registration order), then
// " <stage>_p99_us=N" for every stage latency that has values, then " key=value" for every
// gauge registered with a log key (always, even when zero). Pure function; allocates.
#pragma once

#include <string>

#include "core/metrics_registry.hpp"

namespace mocap {

[[nodiscard]] std::string render_log_line(const MetricsSnapshot& snapshot);

}  // namespace mocap
