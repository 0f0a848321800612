// daemon_stats.cpp — what the daemon reports: the Stats reply, /metrics, /healthz and the
// periodic log line, gathered from ingest, the pipeline and its outputs.
#include <spdlog/spdlog.h>

#include "daemon/daemon.hpp"

namespace mocap::daemon {

namespace {

serve::StageLatencySummary summarize(std::string stage, const LatencySnapshot& s) {
    serve::StageLatencySummary out;
    out.stage = std::move(stage);
    out.count = s.count;
    out.p50_us = static_cast<double>(s.percentile_us(50));
    out.p90_us = static_cast<double>(s.percentile_us(90));
    out.p99_us = static_cast<double>(s.percentile_us(99));
    out.max_us = static_cast<double>(s.max_us);
    return out;
}

void append(std::vector<serve::NamedCounter>& out, const CounterGroup& g) {
    for (const auto& c : g.snapshot())
        out.push_back({g.component() + "." + c.name, c.value});
}

}  // namespace

serve::StatsSnapshot Daemon::stats() const {
    serve::StatsSnapshot s;
    if (sink_listener_) append(s.counters, sink_listener_->counters());
    for (const auto& r : can_readers_)
        append(s.counters, r->counters());
    if (!pipeline_) return s;
    append(s.counters, pipeline_->route_counters());
    append(s.counters, pipeline_->pool().counters());
    append(s.counters, pipeline_->assemblers().counters());
    append(s.counters, pipeline_->solver().counters());
    std::vector<CounterValue> outputs;
    for (const auto& o : pipeline_->outputs())
        o->append_counters(outputs);
    for (auto& c : outputs)
        s.counters.push_back({std::move(c.name), c.value});
    const LatencySnapshot ingest = pipeline_->ingest_latency();
    // A sink clock ahead of the host gives negative latencies: not in the histogram, counted.
    s.counters.push_back({"latency.ingest_negative", ingest.negative});
    s.latencies.push_back(summarize("ingest", ingest));
    s.latencies.push_back(summarize("queue_wait", pipeline_->pool().queue_wait_snapshot()));
    s.latencies.push_back(summarize("filter", pipeline_->pool().filter_snapshot()));
    s.latencies.push_back(summarize("assembly", pipeline_->assemblers().assembly_snapshot()));
    return s;
}

// --- web endpoint (docs/viewer.md) ---
serve::MetricsSnapshot Daemon::metrics() const {
    serve::MetricsSnapshot m;
    m.counters = stats().counters;
    if (pose_) {
        for (auto& c : pose_->server().counter_snapshot())
            m.counters.push_back(std::move(c));
    }
    auto gauge = [&m](std::string name, std::string help, double value) {
        m.gauges.push_back({std::move(name), std::move(help), value});
    };
    if (pipeline_) {
        std::vector<pipeline::OutputGauge> gauges;
        for (const auto& o : pipeline_->outputs())
            o->append_gauges(gauges);
        for (auto& g : gauges)
            gauge(std::move(g.name), std::move(g.help), g.value);
    }
    if (sink_listener_) {
        const auto& g = sink_listener_->counters();
        const auto opened = g.value("connections_accepted").value_or(0);
        const auto closed = g.value("connections_closed").value_or(0);
        gauge("sinks_connected", "Sink TCP connections open now",
              static_cast<double>(opened - std::min(opened, closed)));
    }
    gauge("subjects_configured", "Subjects the pipeline was built for",
          static_cast<double>(pipeline_ ? pipeline_->assemblers().subject_count() : 0));
    gauge("start_time_seconds", "Start of mocapd, Unix time in seconds", static_cast<double>(start_us_) * 1e-6);
    if (pipeline_) {
        m.latencies.push_back({"ingest", pipeline_->ingest_latency()});
        m.latencies.push_back({"queue_wait", pipeline_->pool().queue_wait_snapshot()});
        m.latencies.push_back({"filter", pipeline_->pool().filter_snapshot()});
        m.latencies.push_back({"assembly", pipeline_->assemblers().assembly_snapshot()});
    }
    return m;
}

// Alive: the assembler loop turns (it wakes at least every 50 ms), the ingest thread's
// io_context runs, and samples that arrive turn into frames within 2 s.
serve::HealthStatus Daemon::health() const {
    constexpr std::int64_t kWindowUs = 2'000'000;
    const std::int64_t now = clock_.now_us();
    if (stopping_.load()) return {false, "stopping"};
    if (now - pipeline_->assembler_alive_us() > kWindowUs) return {false, "assembler thread stalled"};
    if (ingest_io_.stopped()) return {false, "ingest thread stopped"};
    const std::int64_t last_sample = pipeline_->last_sample_us();
    if (last_sample == 0) return {true, "no sink data yet"};
    std::int64_t last_frame = pipeline_->first_sample_us();
    for (const auto& o : pipeline_->outputs())
        last_frame = std::max(last_frame, o->last_frame_us());
    if (now - last_sample <= kWindowUs && now - last_frame > kWindowUs)
        return {false, "samples arrive but no frame was assembled for 2 s"};
    return {true, "ok"};
}
// --- end web endpoint ---

void Daemon::log_stats() {
    const auto s = stats();
    std::string line;
    for (const auto& c : s.counters) {
        if (c.value != 0) line += " " + c.name + "=" + std::to_string(c.value);
    }
    if (pose_) {
        for (const auto& c : pose_->server().counter_snapshot()) {
            if (c.value != 0) line += " " + c.name + "=" + std::to_string(c.value);
        }
    }
    for (const auto& l : s.latencies) {
        if (l.count != 0) line += fmt::format(" {}_p99_us={:.0f}", l.stage, l.p99_us);
    }
    spdlog::info("stats:{} clients={}", line, pose_ ? pose_->server().client_count() : 0);
}

}  // namespace mocap::daemon
