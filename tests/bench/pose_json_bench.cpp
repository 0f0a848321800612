// The WebSocket frame JSON, encoded once per published frame (http_server.hpp): the
// product's writer (serve/pose_json.cpp) against the same message built as an
// nlohmann::ordered_json and dumped, side by side on the same frame in one run, so the
// choice in pose_json.cpp rests on a measurement (docs/performance.md has the numbers).
// Run: build/tests/bench/pose_json_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "serve/pose_json.hpp"

namespace mocap::serve {
namespace {

struct Sample {
    SubjectFrame frame;
    SkeletonPose pose;
    explicit Sample(std::uint16_t segments) {
        frame.subject_id = 3;
        frame.sync = 123456;
        frame.sample_us = 1'700'000'000'000'000;
        frame.times = {1'700'000'000'000'100, 1'700'000'000'000'300, 1'700'000'000'000'900, 1'700'000'000'001'200};
        frame.segment_count = pose.segment_count = segments;
        for (std::uint16_t i = 0; i < segments; ++i) {
            // Realistic values: unit quaternions and positions around a standing body.
            const double a = 0.37 * i + 0.11;
            pose.q_world_segment_wxyz[i] = {std::cos(a), 0.3 * std::sin(a), 0.9 * std::sin(a), 0.3 * std::sin(a)};
            pose.position_m[i] = {0.123456 * i, -0.0471 * i, 0.9 + 0.05 * i};
            frame.segments[i].flags = kSegmentCalibrated;
        }
    }
};

double round_to(double v, double scale) {
    return std::isfinite(v) ? std::round(v * scale) / scale : v;
}

// The same message, the same rounding (4 decimals for metres, 5 for quaternions).
std::string frame_json_nlohmann(const SubjectFrame& frame, const SkeletonPose& pose, std::int64_t encoded_us) {
    const std::size_t n = std::min<std::size_t>(frame.segment_count, pose.segment_count);
    const StageTimes& t = frame.times;
    nlohmann::ordered_json j{{"type", "frame"},
                             {"subject", frame.subject_id},
                             {"sync", frame.sync},
                             {"sample_us", frame.sample_us},
                             {"stamps",
                              {{"sink_send_us", t.sink_send_us},
                               {"received_us", t.received_us},
                               {"filtered_us", t.filtered_us},
                               {"assembled_us", t.assembled_us},
                               {"encoded_us", encoded_us}}}};
    nlohmann::ordered_json pos = nlohmann::ordered_json::array();
    nlohmann::ordered_json q = nlohmann::ordered_json::array();
    nlohmann::ordered_json flags = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 3; ++k)
            pos.push_back(round_to(pose.position_m[i][k], 1e4));
        for (std::size_t k = 0; k < 4; ++k)
            q.push_back(round_to(pose.q_world_segment_wxyz[i][k], 1e5));
        flags.push_back(static_cast<unsigned>(frame.segments[i].flags | pose.extra_flags[i]));
    }
    j["pos"] = std::move(pos);
    j["q"] = std::move(q);
    j["flags"] = std::move(flags);
    return j.dump();
}

template <class Encode>
void run(benchmark::State& state, Encode encode) {
    Sample s(static_cast<std::uint16_t>(state.range(0)));
    // Both texts describe the same frame (checked once, outside the timed loop).
    if (nlohmann::json::parse(encode_frame_json(s.frame, s.pose, 7)) !=
        nlohmann::json::parse(frame_json_nlohmann(s.frame, s.pose, 7))) {
        state.SkipWithError("the two encoders disagree");
        return;
    }
    std::int64_t t = 0;
    std::size_t bytes = 0;
    for (auto _ : state) {
        s.frame.sync = static_cast<std::uint64_t>(++t);
        const std::string out = encode(s.frame, s.pose, t);
        bytes = out.size();
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["bytes"] = static_cast<double>(bytes);
}

void BM_FrameJson_Lean(benchmark::State& state) {
    run(state, encode_frame_json);
}
void BM_FrameJson_Nlohmann(benchmark::State& state) {
    run(state, frame_json_nlohmann);
}
BENCHMARK(BM_FrameJson_Lean)->Arg(15)->Arg(32);
BENCHMARK(BM_FrameJson_Nlohmann)->Arg(15)->Arg(32);

}  // namespace
}  // namespace mocap::serve

BENCHMARK_MAIN();
