// The WebSocket frame JSON, encoded once per published frame (http_server.hpp): the
// product's encoder (serve/pose_json.cpp, nlohmann::json) against the hand-written fmt
// writer it replaced, side by side on the same frame in one run, so the choice rests on a
// measurement (docs/performance.md has the numbers).
// Run: build/tests/bench/pose_json_bench
#include <benchmark/benchmark.h>

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <nlohmann/json.hpp>

#include "serve/pose_json.hpp"

namespace mocap::serve {
namespace {

struct Sample {
    SubjectFrame frame;
    skeleton::SkeletonPose pose;
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

// The writer the product used before nlohmann (fmt, fixed decimals), kept as the baseline:
// 4 decimals for metres, 5 for quaternions, null for a non-finite value.
void append_number(std::string& out, double v, int decimals) {
    if (!std::isfinite(v)) {
        out += "null";
        return;
    }
    fmt::format_to(std::back_inserter(out), "{:.{}f}", v, decimals);
}

std::string frame_json_fmt(const SubjectFrame& frame, const skeleton::SkeletonPose& pose, std::int64_t encoded_us) {
    const std::size_t n = std::min<std::size_t>(frame.segment_count, pose.segment_count);
    std::string out;
    out.reserve(256 + n * 96);
    const StageTimes& t = frame.times;
    fmt::format_to(std::back_inserter(out),
                   R"({{"type":"frame","subject":{},"sync":{},"sample_us":{},"stamps":{{"sink_send_us":{},)"
                   R"("received_us":{},"filtered_us":{},"assembled_us":{},"encoded_us":{}}},"pos":[)",
                   frame.subject_id, frame.sync, frame.sample_us, t.sink_send_us, t.received_us, t.filtered_us,
                   t.assembled_us, encoded_us);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 3; ++k) {
            if (i + k) out += ',';
            append_number(out, pose.position_m[i][k], 4);
        }
    }
    out += R"(],"q":[)";
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 4; ++k) {
            if (i + k) out += ',';
            append_number(out, pose.q_world_segment_wxyz[i][k], 5);
        }
    }
    out += R"(],"flags":[)";
    for (std::size_t i = 0; i < n; ++i) {
        fmt::format_to(std::back_inserter(out), "{}{}", i ? "," : "",
                       static_cast<unsigned>(frame.segments[i].flags | pose.extra_flags[i]));
    }
    out += "]}";
    return out;
}

template <class Encode>
void run(benchmark::State& state, Encode encode) {
    Sample s(static_cast<std::uint16_t>(state.range(0)));
    // Both texts describe the same frame (checked once, outside the timed loop).
    if (nlohmann::json::parse(encode_frame_json(s.frame, s.pose, 7)) !=
        nlohmann::json::parse(frame_json_fmt(s.frame, s.pose, 7))) {
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

void BM_FrameJson_BeforeFmt(benchmark::State& state) {
    run(state, frame_json_fmt);
}
void BM_FrameJson_Nlohmann(benchmark::State& state) {
    run(state, encode_frame_json);
}
BENCHMARK(BM_FrameJson_BeforeFmt)->Arg(15)->Arg(32);
BENCHMARK(BM_FrameJson_Nlohmann)->Arg(15)->Arg(32);

}  // namespace
}  // namespace mocap::serve

BENCHMARK_MAIN();
