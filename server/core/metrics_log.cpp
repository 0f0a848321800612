// metrics_log.cpp — see the header for the format.
#include "core/metrics_log.hpp"

#include <cmath>

namespace mocap {

std::string render_log_line(const MetricsSnapshot& snapshot) {
    std::string line;
    for (const CounterValue& c : snapshot.counters) {
        if (c.value != 0) line += " " + c.name + "=" + std::to_string(c.value);
    }
    for (const LatencyValue& l : snapshot.latencies) {
        if (l.snapshot.count != 0) line += " " + l.stage + "_p99_us=" + std::to_string(l.snapshot.percentile_us(99));
    }
    for (const GaugeValue& g : snapshot.gauges) {
        if (g.log_key.empty()) continue;
        line += " " + g.log_key + "=" + std::to_string(std::llround(g.value));
    }
    return line;
}

}  // namespace mocap
