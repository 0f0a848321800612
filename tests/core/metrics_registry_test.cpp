// The metrics registry (core/metrics_registry.hpp) and its log-line renderer
// (core/metrics_log.hpp).
#include "core/metrics_registry.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "core/metrics_log.hpp"
#include "core/subject_assembler.hpp"
#include "core/worker_pool.hpp"

namespace mocap {
namespace {

TEST(MetricsRegistry, SnapshotNamesCountersByComponentInRegistrationOrder) {
    Counter accepted, closed;
    SingleWriterCounter routed, routed_other_thread;
    CounterGroup ingest("ingest_tcp"), route("route");
    ingest.add("connections_accepted", accepted);
    ingest.add("connections_closed", closed);
    route.add("samples_routed", routed);
    route.add("samples_routed", routed_other_thread);  // parts summed under one name

    MetricsRegistry registry;
    registry.add(route);
    registry.add(ingest);
    accepted.add(3);
    routed.add(5);
    routed_other_thread.add(2);

    const MetricsSnapshot s = registry.snapshot();
    ASSERT_EQ(s.counters.size(), 3u);
    EXPECT_EQ(s.counters[0].name, "route.samples_routed");
    EXPECT_EQ(s.counters[0].value, 7u);
    EXPECT_EQ(s.counters[1].name, "ingest_tcp.connections_accepted");
    EXPECT_EQ(s.counters[1].value, 3u);
    EXPECT_EQ(s.counters[2].name, "ingest_tcp.connections_closed");
    EXPECT_EQ(s.counters[2].value, 0u);
    EXPECT_TRUE(s.gauges.empty());
    EXPECT_TRUE(s.latencies.empty());
}

TEST(MetricsRegistry, GaugesAndLatenciesAreReadOnEverySnapshot) {
    std::atomic<int> clients{1};
    SingleWriterLatencyHistogram ingest;
    LatencyHistogram filter;
    MetricsRegistry registry;
    registry.add_gauge(
        "pose_clients", "clients now", [&] { return static_cast<double>(clients.load()); }, "clients");
    registry.add_latency("ingest", [&] { return ingest.snapshot(); }, {.negative_counter = true});
    registry.add_latency("filter", [&] { return filter.snapshot(); });

    ingest.record(10);
    ingest.record(-4);
    filter.record(7);
    clients = 4;
    MetricsSnapshot s = registry.snapshot();
    ASSERT_EQ(s.gauges.size(), 1u);
    EXPECT_EQ(s.gauges[0].name, "pose_clients");
    EXPECT_EQ(s.gauges[0].help, "clients now");
    EXPECT_EQ(s.gauges[0].log_key, "clients");
    EXPECT_EQ(s.gauges[0].value, 4.0);
    ASSERT_EQ(s.latencies.size(), 2u);
    EXPECT_EQ(s.latencies[0].stage, "ingest");
    EXPECT_EQ(s.latencies[0].snapshot.count, 1u);
    EXPECT_EQ(s.latencies[1].stage, "filter");
    EXPECT_EQ(s.latencies[1].snapshot.max_us, 7u);
    // Only the stage that asked for it publishes its negatives as a counter.
    ASSERT_EQ(s.counters.size(), 1u);
    EXPECT_EQ(s.counters[0].name, "latency.ingest_negative");
    EXPECT_EQ(s.counters[0].value, 1u);

    clients = 0;
    ingest.record(-1);
    s = registry.snapshot();
    EXPECT_EQ(s.gauges[0].value, 0.0);
    EXPECT_EQ(s.counters[0].value, 2u);
}

// Built once, read by many threads while the components' own threads keep counting.
TEST(MetricsRegistry, ReadersOnAnyThreadSeeValuesOnlyGoUp) {
    SingleWriterCounter samples;
    CounterGroup group("route");
    group.add("samples_routed", samples);
    SingleWriterLatencyHistogram h;
    MetricsRegistry registry;
    registry.add(group);
    registry.add_latency("ingest", [&] { return h.snapshot(); });

    constexpr std::uint64_t kAdds = 200'000;
    std::atomic<bool> done{false};
    std::vector<std::thread> readers;
    std::atomic<int> regressions{0};
    for (int r = 0; r < 2; ++r) {
        readers.emplace_back([&] {
            std::uint64_t last = 0, last_count = 0;
            while (!done.load()) {
                const MetricsSnapshot s = registry.snapshot();
                if (s.counters[0].value < last || s.latencies[0].snapshot.count < last_count) ++regressions;
                last = s.counters[0].value;
                last_count = s.latencies[0].snapshot.count;
            }
        });
    }
    std::thread writer([&] {
        for (std::uint64_t i = 0; i < kAdds; ++i) {
            samples.add();
            h.record(static_cast<std::int64_t>(i % 1000));
        }
    });
    writer.join();
    done = true;
    for (auto& t : readers)
        t.join();
    EXPECT_EQ(regressions.load(), 0);
    const MetricsSnapshot s = registry.snapshot();
    EXPECT_EQ(s.counters[0].value, kAdds);
    EXPECT_EQ(s.latencies[0].snapshot.count, kAdds);
}

class NullSink : public FrameSink {
public:
    void on_frame(const SubjectFrame&) override {}
};

// Core components register everything they count or time, under their documented names.
TEST(MetricsRegistry, CoreComponentsRegisterTheirCountersGaugesAndStages) {
    WorkerPoolConfig pc;
    pc.workers = 1;
    WorkerPool pool(pc);
    NullSink sink;
    AssemblerSet assemblers(AssemblerConfig{}, sink);
    assemblers.add_subject(1, 3);
    assemblers.add_subject(2, 3);
    MetricsRegistry registry;
    pool.register_metrics(registry);
    assemblers.register_metrics(registry);

    const MetricsSnapshot s = registry.snapshot();
    std::vector<std::string> stages;
    for (const auto& l : s.latencies)
        stages.push_back(l.stage);
    EXPECT_EQ(stages, (std::vector<std::string>{"queue_wait", "filter", "assembly"}));
    ASSERT_EQ(s.gauges.size(), 1u);
    EXPECT_EQ(s.gauges[0].name, "subjects_configured");
    EXPECT_EQ(s.gauges[0].value, 2.0);
    const auto has = [&](const std::string& name) {
        for (const auto& c : s.counters) {
            if (c.name == name) return true;
        }
        return false;
    };
    EXPECT_TRUE(has("worker_pool.samples_submitted"));
    EXPECT_TRUE(has("assembler.poses_unknown_subject"));
    EXPECT_EQ(s.counters.size(), pool.counters().snapshot().size() + assemblers.counters().snapshot().size());
}

TEST(MetricsLogLine, NonzeroCountersThenP99ThenLoggedGauges) {
    MetricsSnapshot s;
    s.counters = {{"route.samples_routed", 42}, {"route.samples_rejected", 0}, {"serve.frames_sent", 7}};
    s.gauges = {{"pose_clients", "clients", 2, "clients"}, {"start_time_seconds", "start", 1.7e9, ""}};
    LatencyHistogram filter, idle;
    filter.record(12);
    filter.record(20);
    s.latencies = {{"filter", filter.snapshot()}, {"assembly", idle.snapshot()}};
    EXPECT_EQ(render_log_line(s), " route.samples_routed=42 serve.frames_sent=7 filter_p99_us=20 clients=2");

    MetricsSnapshot quiet;
    quiet.gauges = {{"pose_clients", "clients", 0, "clients"}};
    EXPECT_EQ(render_log_line(quiet), " clients=0");
}

}  // namespace
}  // namespace mocap
