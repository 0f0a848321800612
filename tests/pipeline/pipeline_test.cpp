#include "pipeline/pipeline.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace mocap::pipeline {
namespace {

class FixedClock final : public Clock {
public:
    [[nodiscard]] std::int64_t now_us() const noexcept override { return 1'000'000; }
};

/// Records what the pipeline hands an output.
class RecordingOutput final : public Output {
public:
    struct Seen {
        std::uint32_t subject = 0;
        std::uint64_t sync = 0;
        std::uint16_t segments = 0;
        std::array<double, 4> q0{};
        std::uint16_t angles = 0;
    };
    std::vector<Seen> frames;
    int started = 0, stopped = 0;

    [[nodiscard]] std::string_view name() const override { return "test"; }
    bool start(std::string* /*error*/) override { return ++started, true; }
    bool stop(std::string* /*error*/) override { return ++stopped, true; }
    void on_frame(const SubjectFrame& f, const skeleton::SkeletonPose& p) override {
        frames.push_back(
            {f.subject_id, f.sync, f.segment_count, f.segments[0].q_earth_sensor_wxyz, p.joint_angle_count});
    }
    void register_metrics(MetricsRegistry& registry) const override {
        registry.add_gauge("test_frames", "Frames this output saw",
                           [this] { return static_cast<double>(frames.size()); });
    }
};

PipelineConfig two_subjects(std::string filter = "mahony") {
    PipelineConfig c;
    c.model = skeleton::default_body_model(1.75, filter);
    c.subjects = {1, 2};
    c.assembler.deadline_us = 20'000;
    return c;
}

SegmentSample raw_sample(std::uint32_t subject, std::uint8_t node, std::uint64_t sync, double gyro_z) {
    SegmentSample s;
    s.subject_id = subject;
    s.node_id = node;
    s.sync = sync;
    s.imu.t_us = static_cast<std::int64_t>(sync) * 10'000;
    s.imu.gyro_rad_s = {0.0, 0.0, gyro_z};
    s.imu.accel_m_s2 = {0.0, 0.0, 9.81};
    s.times.received_us = s.imu.t_us;
    return s;
}

std::uint64_t counter(const Pipeline& p, std::string_view name) {
    return p.route_counters().value(name).value_or(~0ull);
}

TEST(Pipeline, NodeTableCoversEveryWireNodeId) {
    FixedClock clock;
    std::string error;
    auto c = two_subjects();
    c.model.segments[3].node_id = 100;  // above the 64 entries the daemon's table once had
    auto p = Pipeline::create(std::move(c), clock, &error);
    ASSERT_TRUE(p) << error;
    EXPECT_EQ(p->segment_of(100), 3);
    EXPECT_EQ(p->segment_of(1), 0);
    EXPECT_EQ(p->segment_of(4), -1);  // node 4 was segment 3's default id
    EXPECT_EQ(p->segment_of(255), -1);
}

TEST(Pipeline, UnknownNodesAndSubjectsAreCountedNotFiltered) {
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    auto out = std::make_unique<RecordingOutput>();
    auto* seen = out.get();
    p->add_output(std::move(out));
    ASSERT_TRUE(p->start_outputs(&error)) << error;
    EXPECT_EQ(p->process(raw_sample(1, 200, 1, 0.0), 10'000), RouteResult::kUnknownNode);  // node not in the model
    EXPECT_EQ(p->process(raw_sample(3, 1, 1, 0.0), 10'000), RouteResult::kUnknownNode);    // subject not configured
    EXPECT_EQ(p->process(raw_sample(0, 1, 1, 0.0), 10'000), RouteResult::kUnknownNode);
    EXPECT_EQ(counter(*p, "samples_unknown_node"), 3u);
    EXPECT_EQ(counter(*p, "samples_routed"), 0u);
    p->flush(1'000'000);
    EXPECT_TRUE(seen->frames.empty());
}

TEST(Pipeline, OnlySamplesOfServedSubjectsCountAsArriving) {
    // /healthz reads "samples arrive" from last_sample_us(): valid samples for nodes outside
    // the body model (or subjects not configured) produce no frame, so they must not count.
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    for (std::uint64_t sync = 1; sync <= 50; ++sync) {
        p->process(raw_sample(1, 40, sync, 0.0), static_cast<std::int64_t>(sync) * 10'000);  // node not in the model
        p->process(raw_sample(3, 1, sync, 0.0), static_cast<std::int64_t>(sync) * 10'000);   // subject not configured
        // The live path: routed from the ingest thread (workers not started).
        p->route(raw_sample(2, 41, sync, 0.0));
    }
    EXPECT_EQ(counter(*p, "samples_unknown_node"), 150u);
    EXPECT_EQ(p->first_sample_us(), 0);
    EXPECT_EQ(p->last_sample_us(), 0);
    EXPECT_EQ(p->ingest_latency().count, 0u);
    EXPECT_EQ(p->process(raw_sample(1, 1, 51, 0.0), 510'000), RouteResult::kProcessed);
    EXPECT_EQ(p->first_sample_us(), 510'000);
    EXPECT_EQ(p->last_sample_us(), 510'000);
    p->route(raw_sample(2, 2, 52, 0.0));  // queued or not, subject 2's segment owes a frame
    EXPECT_EQ(p->last_sample_us(), 520'000);
}

TEST(Pipeline, IngestLatencyIsPerSubjectAndSaturates) {
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    for (std::uint64_t sync = 1; sync <= 20; ++sync) {
        auto honest = raw_sample(1, 1, sync, 0.0);
        honest.times.sink_send_us = honest.times.received_us - 2'000;  // 2 ms
        p->process(honest, honest.times.received_us);
        // A replayed file (or anything past ingest's check) with a hostile stamp: the
        // difference saturates instead of overflowing, and stays in subject 2's figure.
        auto hostile = raw_sample(2, 1, sync, 0.0);
        hostile.times.sink_send_us = sync % 2 ? std::numeric_limits<std::int64_t>::min() + 1 : 1;
        p->process(hostile, hostile.times.received_us);
    }
    const LatencySnapshot one = p->ingest_latency(1);
    EXPECT_EQ(one.count, 20u);
    EXPECT_EQ(one.max_us, 2'000u);
    EXPECT_EQ(one.percentile_us(99), 2'000u);
    const LatencySnapshot two = p->ingest_latency(2);
    EXPECT_EQ(two.count, 20u);
    EXPECT_EQ(two.negative, 0u) << "no wrap to a negative value";
    EXPECT_EQ(two.max_us, static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()));
    EXPECT_EQ(p->ingest_latency().count, 40u) << "the merged figure holds both";
    EXPECT_EQ(p->ingest_latency(7).count, 0u) << "not configured";
}

TEST(Pipeline, NonFiniteSamplesAreRejectedBeforeTheFilter) {
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    auto s = raw_sample(1, 1, 1, std::numeric_limits<double>::quiet_NaN());
    EXPECT_EQ(p->process(s, 10'000), RouteResult::kRejected);
    EXPECT_EQ(counter(*p, "samples_rejected"), 1u);
}

TEST(Pipeline, EachSubjectAndSegmentHasItsOwnFilter) {
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    auto out = std::make_unique<RecordingOutput>();
    auto* seen = out.get();
    p->add_output(std::move(out));
    ASSERT_TRUE(p->start_outputs(&error)) << error;
    const auto segments = static_cast<std::uint8_t>(p->model().size());
    // Subject 1 turns about z, subject 2 stands still: their pelvis filters must differ,
    // and every segment's sample reaches the frame of its own subject.
    for (std::uint64_t sync = 1; sync <= 50; ++sync) {
        const std::int64_t now = static_cast<std::int64_t>(sync) * 10'000;
        for (std::uint8_t node = 1; node <= segments; ++node) {
            ASSERT_EQ(p->process(raw_sample(1, node, sync, 1.0), now), RouteResult::kProcessed);
            ASSERT_EQ(p->process(raw_sample(2, node, sync, 0.0), now), RouteResult::kProcessed);
        }
    }
    p->flush(1'000'000);
    EXPECT_EQ(counter(*p, "samples_routed"), 2u * 50u * segments);
    ASSERT_EQ(seen->frames.size(), 100u);  // every instant of both subjects was complete
    const auto last_of = [&](std::uint32_t subject) {
        for (auto it = seen->frames.rbegin(); it != seen->frames.rend(); ++it) {
            if (it->subject == subject) return *it;
        }
        return RecordingOutput::Seen{};
    };
    const auto turning = last_of(1), still = last_of(2);
    EXPECT_EQ(turning.sync, 50u);
    EXPECT_EQ(still.sync, 50u);
    EXPECT_EQ(turning.segments, segments);
    EXPECT_GT(turning.angles, 0u);
    EXPECT_NEAR(still.q0[0], 1.0, 1e-6);       // no rotation: identity
    EXPECT_LT(std::abs(turning.q0[0]), 0.99);  // ~0.5 rad about z: w ~ cos(0.25)
    EXPECT_GT(std::abs(turning.q0[3]), 0.15);
    ASSERT_TRUE(p->stop_outputs(&error)) << error;
    EXPECT_EQ(seen->started, 1);
    EXPECT_EQ(seen->stopped, 1);
}

TEST(Pipeline, UnknownFilterNamesTheSegment) {
    FixedClock clock;
    std::string error;
    auto c = two_subjects();
    c.model.segments[2].filter = "nope";
    EXPECT_FALSE(Pipeline::create(std::move(c), clock, &error));
    EXPECT_NE(error.find("filter for segment"), std::string::npos) << error;
}

// One registration call publishes every stage's metrics and the outputs' own: what the
// daemon's Stats, /metrics and log line render (docs/performance.md, "Metrics registry").
TEST(Pipeline, RegistersEveryStageAndOutputMetric) {
    FixedClock clock;
    std::string error;
    auto p = Pipeline::create(two_subjects(), clock, &error);
    ASSERT_TRUE(p) << error;
    p->add_output(std::make_unique<RecordingOutput>());
    MetricsRegistry registry;
    p->register_metrics(registry);
    ASSERT_TRUE(p->start_outputs(&error)) << error;
    for (std::uint64_t sync = 1; sync <= 3; ++sync) {
        for (std::uint8_t node = 1; node <= 15; ++node)
            p->process(raw_sample(1, node, sync, 0.1), static_cast<std::int64_t>(sync) * 10'000);
    }
    p->process(raw_sample(1, 200, 4, 0.0), 40'000);
    p->flush(1'000'000);

    const MetricsSnapshot s = registry.snapshot();
    std::map<std::string, std::uint64_t> counters;
    for (const auto& c : s.counters)
        EXPECT_TRUE(counters.emplace(c.name, c.value).second) << "registered twice: " << c.name;
    EXPECT_EQ(counters.at("route.samples_routed"), 45u);
    EXPECT_EQ(counters.at("route.samples_unknown_node"), 1u);
    EXPECT_EQ(counters.count("latency.ingest_negative"), 1u);
    for (const char* component : {"worker_pool.", "assembler.", "skeleton."}) {
        EXPECT_TRUE(std::any_of(counters.begin(), counters.end(), [&](const auto& c) {
            return c.first.rfind(component, 0) == 0;
        })) << component;
    }
    EXPECT_GE(counters.at("skeleton.frames_solved"), 3u);
    std::vector<std::string> stages;
    for (const auto& l : s.latencies)
        stages.push_back(l.stage);
    EXPECT_EQ(stages, (std::vector<std::string>{"ingest", "queue_wait", "filter", "assembly"}));
    std::map<std::string, double> gauges;
    for (const auto& g : s.gauges)
        gauges[g.name] = g.value;
    EXPECT_EQ(gauges.at("subjects_configured"), 2.0);
    EXPECT_GE(gauges.at("test_frames"), 3.0);
}

}  // namespace
}  // namespace mocap::pipeline
