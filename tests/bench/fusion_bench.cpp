// fusion_bench — what the chain stage costs a subject (docs/fusion.md, "Cost"): the pipeline
// in its synchronous mode (pipeline.hpp: the same routing, filters, assembly and solve as a
// live run, on one thread) over 60 s of the simulator's walk, 15 segments at 100 Hz with
// MEMS noise, once with [fusion] heading = "magnetometer" (the chain off) and once with
// "auto" (and "auto" with learned axes), side by side in one binary; in a clean field and over
// the simulator's steel floor (where auto holds more joints by their constraints).
//
// Each benchmark iteration is one whole take; the counters are per SYNC instant (15 samples
// and one solved frame): ns_per_instant (mean) and p99_us (the 99th percentile of one
// instant's time: the latency the chain can add to a frame). CPU per subject is
// ns_per_instant × 100 Hz.
//   cmake --build build -j2 --target fusion_bench
//   build/tests/bench/fusion_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <random>
#include <vector>

#include "core/clock.hpp"
#include "pipeline/pipeline.hpp"
#include "sim/magnetic_env.hpp"
#include "sim/stream_motion.hpp"
#include "sim/stream_node.hpp"

namespace mocap {
namespace {

class FixedClock final : public Clock {
public:
    [[nodiscard]] std::int64_t now_us() const noexcept override { return 0; }
};

constexpr double kRateHz = 100.0;
constexpr double kTakeS = 60.0;

/// The walk's samples for every segment, instant by instant (T-pose first, so the subject
/// calibrates itself as in a live run), in the magnetic environment `env` (a mocap-sim preset).
std::vector<SegmentSample> walk_samples(const char* env_name) {
    const sim::MagneticEnv env(*sim::make_magnetic_env_spec(env_name, 1));
    const skeleton::BodyModel model = skeleton::default_body_model(1.75, "mocap");
    const sim::StreamMotion motion = sim::StreamMotion::walk(model, 2.0);
    std::mt19937 rng(1);
    std::normal_distribution<double> n(0.0, 1.0);
    const sim::NodeSensorNoise noise = sim::stream_node_noise(1.0);
    std::vector<math::Quat> mount(model.size());
    for (std::size_t i = 0; i < model.size(); ++i)
        mount[i] = math::quat_from_rotvec(0.3 * math::to_vec3(Vec3d{n(rng), n(rng), n(rng)}));
    std::vector<SegmentSample> out;
    const double dt = 1.0 / kRateHz;
    sim::BodyPose prev, now, next;
    motion.pose(0.0, 0.0, math::Vec3::Zero(), prev);
    const auto jitter = [&](double sigma) {
        std::array<double, 3> v{};
        for (double& x : v)
            x = sigma * n(rng);
        return v;
    };
    const auto plus = [](const math::Vec3& a, const std::array<double, 3>& b) {
        return Vec3d{a.x() + b[0], a.y() + b[1], a.z() + b[2]};
    };
    for (int k = 1; k * dt <= kTakeS; ++k) {
        const double t = k * dt;
        motion.pose(t, 0.0, math::Vec3::Zero(), now);
        motion.pose(t + dt, 0.0, math::Vec3::Zero(), next);
        for (std::size_t i = 0; i < model.size(); ++i) {
            const math::Vec3 acc =
                (next.sensor_position_m[i] - 2.0 * now.sensor_position_m[i] + prev.sensor_position_m[i]) / (dt * dt);
            const sim::SensorReading r =
                sim::ideal_reading(prev.q_earth_segment[i] * mount[i], now.q_earth_segment[i] * mount[i], dt, acc,
                                   env.uniform() ? sim::stream_mag_earth_ut() : env.field_ut(now.sensor_position_m[i]));
            SegmentSample s;
            s.subject_id = 1;
            s.segment_index = static_cast<std::uint16_t>(i);
            s.node_id = static_cast<std::uint8_t>(model.segments[i].node_id);
            s.sync = static_cast<std::uint64_t>(k);
            s.imu.t_us = static_cast<std::int64_t>(k) * 10'000;
            s.imu.gyro_rad_s = plus(r.gyro_rad_s, jitter(noise.gyro_rad_s));
            s.imu.accel_m_s2 = plus(r.accel_m_s2, jitter(noise.accel_m_s2));
            s.imu.mag_ut = plus(r.mag_ut, jitter(noise.mag_ut));
            out.push_back(s);
        }
        prev = now;
    }
    return out;
}

const std::vector<SegmentSample>& samples(bool steel_floor) {
    static const std::vector<SegmentSample> clean = walk_samples("clean");
    static const std::vector<SegmentSample> steel = walk_samples("steel-floor");
    return steel_floor ? steel : clean;
}

void run(benchmark::State& state, fusion::HeadingMode mode, bool estimate_axes, bool steel_floor = false) {
    const std::vector<SegmentSample>& all = samples(steel_floor);
    FixedClock clock;
    std::vector<double> instant_us;
    instant_us.reserve(all.size() / 15);
    double total_ns = 0.0;
    std::size_t instants = 0;
    for (auto _ : state) {
        state.PauseTiming();
        pipeline::PipelineConfig pc;
        pc.model = skeleton::default_body_model(1.75, "mocap");
        pc.subjects = {1};
        pc.solver.auto_calibrate = skeleton::CalibrationPose::kTPose;
        pc.solver.fusion.chain.mode = mode;
        pc.solver.fusion.estimate_axes = estimate_axes;
        std::string error;
        auto p = pipeline::Pipeline::create(std::move(pc), clock, &error);
        if (!p) {
            state.SkipWithError(error.c_str());
            return;
        }
        instant_us.clear();
        state.ResumeTiming();
        const auto start = std::chrono::steady_clock::now();
        for (std::size_t i = 0; i < all.size(); i += 15) {
            const auto t0 = std::chrono::steady_clock::now();
            for (std::size_t k = i; k < i + 15 && k < all.size(); ++k)
                p->process(all[k], all[k].imu.t_us);
            instant_us.push_back(
                std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
        }
        total_ns += std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start).count();
        instants += instant_us.size();
    }
    std::sort(instant_us.begin(), instant_us.end());
    state.counters["ns_per_instant"] = total_ns / static_cast<double>(std::max<std::size_t>(instants, 1));
    state.counters["p99_us"] = instant_us.empty() ? 0.0 : instant_us[instant_us.size() * 99 / 100];
}

void BM_WalkChainOff(benchmark::State& state) {
    run(state, fusion::HeadingMode::kMagnetometer, false);
}
void BM_WalkChainAuto(benchmark::State& state) {
    run(state, fusion::HeadingMode::kAuto, false);
}
void BM_WalkChainAutoEstimateAxes(benchmark::State& state) {
    run(state, fusion::HeadingMode::kAuto, true);
}
void BM_SteelFloorWalkChainOff(benchmark::State& state) {
    run(state, fusion::HeadingMode::kMagnetometer, false, true);
}
void BM_SteelFloorWalkChainAuto(benchmark::State& state) {
    run(state, fusion::HeadingMode::kAuto, false, true);
}
BENCHMARK(BM_WalkChainOff)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_WalkChainAuto)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_WalkChainAutoEstimateAxes)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_SteelFloorWalkChainOff)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_SteelFloorWalkChainAuto)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace
}  // namespace mocap

BENCHMARK_MAIN();
