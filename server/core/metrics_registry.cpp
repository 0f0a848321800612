// metrics_registry.cpp — registration bookkeeping and the snapshot every renderer reads.
// Nothing here is on a hot path (see the header's contract).
#include "core/metrics_registry.hpp"

namespace mocap {

void MetricsRegistry::add(const CounterGroup& group) {
    groups_.push_back(&group);
}

void MetricsRegistry::add_gauge(std::string name, std::string help, std::function<double()> read, std::string log_key) {
    gauges_.push_back(Gauge{std::move(name), std::move(help), std::move(log_key), std::move(read)});
}

void MetricsRegistry::add_latency(std::string stage, std::function<LatencySnapshot()> read, LatencyOptions options) {
    latencies_.push_back(Latency{std::move(stage), std::move(read), options});
}

MetricsSnapshot MetricsRegistry::snapshot() const {
    MetricsSnapshot out;
    for (const CounterGroup* g : groups_) {
        for (CounterValue& c : g->snapshot())
            out.counters.push_back(CounterValue{g->component() + "." + c.name, c.value});
    }
    out.gauges.reserve(gauges_.size());
    for (const Gauge& g : gauges_)
        out.gauges.push_back(GaugeValue{g.name, g.help, g.read(), g.log_key});
    out.latencies.reserve(latencies_.size());
    for (const Latency& l : latencies_) {
        out.latencies.push_back(LatencyValue{l.stage, l.read()});
        if (l.options.negative_counter) {
            out.counters.push_back(
                CounterValue{"latency." + l.stage + "_negative", out.latencies.back().snapshot.negative});
        }
    }
    return out;
}

}  // namespace mocap
