// The Stats reply rendered from a registry snapshot (serve/stats_reply.hpp).
#include "serve/stats_reply.hpp"

#include <gtest/gtest.h>

#include "mocap/v1/mocap.pb.h"

namespace mocap::serve {
namespace {

TEST(StatsReply, CountersKeepTheirNamesAndLatenciesAreSummarised) {
    Counter sent;
    CounterGroup serve("serve");
    serve.add("frames_sent", sent);
    sent.add(9);
    LatencyHistogram filter;
    for (int v = 1; v <= 100; ++v)
        filter.record(v);
    filter.record(-3);
    MetricsRegistry registry;
    registry.add(serve);
    registry.add_gauge(
        "pose_clients", "clients now", [] { return 3.0; }, "clients");
    registry.add_latency("filter", [&] { return filter.snapshot(); }, {.negative_counter = true});

    v1::Stats stats;
    stats.set_request_id(77);
    render_stats(registry.snapshot(), stats);
    EXPECT_EQ(stats.request_id(), 77u);
    ASSERT_EQ(stats.counters_size(), 2);
    EXPECT_EQ(stats.counters(0).name(), "serve.frames_sent");
    EXPECT_EQ(stats.counters(0).value(), 9u);
    EXPECT_EQ(stats.counters(1).name(), "latency.filter_negative");
    EXPECT_EQ(stats.counters(1).value(), 1u);
    ASSERT_EQ(stats.latencies_size(), 1);
    const v1::StageLatency& l = stats.latencies(0);
    EXPECT_EQ(l.stage(), "filter");
    EXPECT_EQ(l.count(), 100u);
    EXPECT_EQ(l.p50_us(), 50.0);  // exact below 32 µs, within 1/32 above (bucket upper bound)
    EXPECT_GE(l.p90_us(), 90.0);
    EXPECT_LE(l.p90_us(), 90.0 * 33 / 32);
    EXPECT_GE(l.p99_us(), 99.0);
    EXPECT_LE(l.p99_us(), 100.0);
    EXPECT_EQ(l.max_us(), 100.0);
}

}  // namespace
}  // namespace mocap::serve
