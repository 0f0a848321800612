// Cost of encoding one frame (the once-per-frame price every subscriber shares).
// Run: build-*/tests/serve/serve_bench
#include <benchmark/benchmark.h>

#include <cmath>

#include "serve/pose_encoder.hpp"

namespace mocap::serve {
namespace {

void BM_EncodeFrame(benchmark::State& state) {
    const auto segments = static_cast<std::uint16_t>(state.range(0));
    const auto fields = static_cast<std::uint32_t>(state.range(1));
    SubjectFrame frame;
    skeleton::SkeletonPose pose;
    frame.segment_count = pose.segment_count = segments;
    for (std::uint16_t i = 0; i < segments; ++i) {
        const double a = 0.1 * i;
        frame.segments[i].q_earth_sensor_wxyz = {std::cos(a), std::sin(a), 0.0, 0.0};
        pose.q_world_segment_wxyz[i] = {std::cos(a), 0.0, std::sin(a), 0.0};
        pose.position_m[i] = {0.1 * i, 0.2, 1.0};
    }
    pose.joint_angle_count = 3 * segments;
    PoseEncoder encoder;
    std::int64_t t = 0;
    std::size_t bytes = 0;
    for (auto _ : state) {
        frame.sync = static_cast<std::uint64_t>(++t);
        const SharedBytes out = encoder.encode_frame(frame, pose, fields, t);
        bytes = out->size();
        benchmark::DoNotOptimize(out.get());
    }
    state.counters["bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_EncodeFrame)
    ->Args({15, kFieldOrientations | kFieldPositions})
    ->Args({15, kFieldAll})
    ->Args({32, kFieldAll});

}  // namespace
}  // namespace mocap::serve

BENCHMARK_MAIN();
