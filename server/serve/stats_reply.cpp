// stats_reply.cpp — see the header.
#include "serve/stats_reply.hpp"

#include "mocap/v1/mocap.pb.h"

namespace mocap::serve {

void render_stats(const MetricsSnapshot& snapshot, v1::Stats& out) {
    for (const CounterValue& c : snapshot.counters) {
        v1::Counter* counter = out.add_counters();
        counter->set_name(c.name);
        counter->set_value(c.value);
    }
    for (const LatencyValue& l : snapshot.latencies) {
        const LatencySnapshot& s = l.snapshot;
        v1::StageLatency* latency = out.add_latencies();
        latency->set_stage(l.stage);
        latency->set_count(s.count);
        latency->set_p50_us(static_cast<double>(s.percentile_us(50)));
        latency->set_p90_us(static_cast<double>(s.percentile_us(90)));
        latency->set_p99_us(static_cast<double>(s.percentile_us(99)));
        latency->set_max_us(static_cast<double>(s.max_us));
    }
}

}  // namespace mocap::serve
