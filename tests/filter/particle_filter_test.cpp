#include "filter/particle_filter.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <numbers>
#include <vector>

#include "seed_filter_fixture.hpp"

// Counts heap allocations so the tests can prove update() allocates nothing.
// g++ 12 at -O2 -g (sanitizer builds) sees gtest's `new TestClass` inlined next to this
// replacement delete and wrongly reports malloc/free as mismatched with new/delete.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
namespace {
std::atomic<long> g_allocations{0};
}  // namespace
void* operator new(std::size_t n) {
    ++g_allocations;
    if (void* p = std::malloc(n ? n : 1)) return p;
    throw std::bad_alloc();
}
void operator delete(void* p) noexcept {
    std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
    std::free(p);
}

namespace mocap::filter {
namespace {

double mean_total(const ParticleFilterParams& p, sim::ScenarioKind kind, std::initializer_list<std::uint64_t> seeds) {
    double s = 0.0;
    for (const std::uint64_t seed : seeds) {
        ParticleFilter f(p);
        s += testing::run(f, sim::make_scenario(kind, seed).rows, 5.0).total_deg;
    }
    return s / static_cast<double>(seeds.size());
}

TEST(ParticleFilter, SameSeedSameOutputOtherSeedOtherOutput) {
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 1);
    ParticleFilterParams p;
    p.particles = 64;
    ParticleFilter a(p), b(p);
    p.seed = 2;
    ParticleFilter c(p);
    bool differs = false;
    for (std::size_t k = 0; k < 1000; ++k) {
        a.update(sc.rows[k].sample);
        b.update(sc.rows[k].sample);
        c.update(sc.rows[k].sample);
        ASSERT_EQ(a.orientation().coeffs(), b.orientation().coeffs()) << k;
        differs |= a.orientation().coeffs() != c.orientation().coeffs();
    }
    EXPECT_TRUE(differs);
    // reset() replays the same sequence.
    a.reset();
    for (std::size_t k = 0; k < 1000; ++k)
        a.update(sc.rows[k].sample);
    EXPECT_EQ(a.orientation().coeffs(), b.orientation().coeffs());
}

TEST(ParticleFilter, InitialisesAroundTheFirstMeasurementNotUniformly) {
    const math::Quat truth0 = math::quat_from_rotvec(math::Vec3(0.7, -0.3, 2.0));
    const auto rows = testing::constant_rate(truth0, math::Vec3::Zero(), 100.0, 0.1);
    ParticleFilter f;
    EXPECT_FALSE(f.state().initialised);
    f.update(rows[0].sample);
    ASSERT_TRUE(f.state().initialised);
    const ParticleFilterParams& p = f.params();
    // The cloud's heading spread is init_heading, its tilt spread init_tilt (earth frame).
    double sum_h2 = 0, sum_t2 = 0;
    for (int i = 0; i < f.particle_count(); ++i) {
        const math::Vec3 e = math::rotvec_from_quat(f.particle(i) * truth0.conjugate());
        sum_h2 += e.z() * e.z();
        sum_t2 += 0.5 * (e.x() * e.x() + e.y() * e.y());
    }
    EXPECT_NEAR(std::sqrt(sum_h2 / f.particle_count()), p.init_heading_rad, 0.2 * p.init_heading_rad);
    EXPECT_NEAR(std::sqrt(sum_t2 / f.particle_count()), p.init_tilt_rad, 0.2 * p.init_tilt_rad);
    EXPECT_LT(math::angle_rad(f.orientation() * truth0.conjugate()), 0.05);
}

TEST(ParticleFilter, TracksNoiselessRotation) {
    const math::Quat truth0 = math::quat_from_rotvec(math::Vec3(0.2, 0.4, -1.0));
    const auto rows = testing::constant_rate(truth0, math::Vec3(0.5, -0.8, 1.5), 100.0, 20.0);
    ParticleFilter f;
    const testing::Rmse r = testing::run(f, rows, 2.0);
    // The cloud is as wide as the noise densities tuned on real sensors make it (~1°), and
    // the bias particles start 1.7°/s apart: measured 1.23° RMSE, 1.99° worst, 0.0058 rad/s.
    EXPECT_LT(r.total_deg, 1.5);
    EXPECT_LT(r.worst_deg, 2.5);
    EXPECT_LT(f.gyro_bias_rad_s().norm(), 0.008);
}

TEST(ParticleFilter, WeightsStayNormalisedAndParticlesUnit) {
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 2);
    ParticleFilter f;
    for (std::size_t k = 0; k < 3000; ++k) {
        f.update(sc.rows[k].sample);
        if (k % 500 != 499) continue;
        double sw = 0, s2 = 0;
        for (int i = 0; i < f.particle_count(); ++i) {
            sw += f.weight(i);
            s2 += f.weight(i) * f.weight(i);
            ASSERT_NEAR(f.particle(i).norm(), 1.0, 1e-9);
        }
        EXPECT_NEAR(sw, 1.0, 1e-9);
        EXPECT_NEAR(f.state().n_eff, 1.0 / s2, 1e-6 * f.state().n_eff);
        EXPECT_LE(f.state().n_eff, f.particle_count() * (1 + 1e-9));
    }
    EXPECT_GT(f.state().resamples, 0u);
}

TEST(ParticleFilter, RealisticScenarioAccuracyAndBias) {
    // MEMS noise, a constant gyro bias up to 2°/s per axis, bursts of linear acceleration.
    // Measured: up to 1.53° total, 1.33° heading RMSE on seeds 1-3 with the defaults.
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
        const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, seed);
        ParticleFilter f;
        const testing::Rmse r = testing::run(f, sc.rows, 5.0);
        EXPECT_LT(r.total_deg, 1.8) << seed;
        EXPECT_LT(r.inclination_deg, 1.2) << seed;
        EXPECT_LT(r.heading_deg, 1.6) << seed;
        EXPECT_LT((f.gyro_bias_rad_s() - sc.gyro_bias_rad_s).norm(), 0.006) << seed;
        EXPECT_EQ(f.state().reinitialisations, 0u);
    }
}

TEST(ParticleFilter, FouratiScenarioWithItsNoiseLevels) {
    // Table II at 100 Hz as densities: gyro 0.4 rad/s per sample = 0.04 rad/s/√Hz;
    // accelerometer 0.4 m/s² = 0.04 g per sample = 0.004 /√Hz (the tilt residual is in g);
    // heading: a field noise of 80% of the field, twice its horizontal part, ~0.16 rad/√Hz.
    ParticleFilterParams p;
    p.gyro_noise = 0.04;
    p.meas_tilt = 0.004;
    p.meas_heading = 0.16;
    p.init_heading_rad = 1.0;
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
        ParticleFilter f(p);
        const testing::Rmse r = testing::run(f, sim::make_scenario(sim::ScenarioKind::fourati, seed).rows, 5.0);
        // Inclination measured 1.06-1.12° over seeds 1-5 (Euler roll 1.7-3.2°: Table I's path
        // passes near pitch ±90°, where roll is ill-conditioned).
        EXPECT_LT(r.inclination_deg, 1.5) << seed;
        EXPECT_LT(r.pitch_deg, 1.5) << seed;
        // Heading under a field noise twice the horizontal field is this filter's weak spot
        // (measured 7-28° on seeds 1-5; the earlier per-sample-σ design reached < 9° on a
        // slower stand-in of Table I's motion), left
        // as an open item in docs/accuracy.md, "Particle filter (pf)"; the bound catches a
        // heading that does not converge at all.
        EXPECT_LT(r.yaw_deg, 45.0) << seed;
    }
}

TEST(ParticleFilter, RegularisationMatters) {
    // Without the kernel the resampled cloud keeps only copies of a few particles, and the
    // bias particles never explore.
    const double base = mean_total({}, sim::ScenarioKind::realistic, {1, 2, 3});
    ParticleFilterParams no_reg;
    no_reg.reg_h = 0.0;
    const double without = mean_total(no_reg, sim::ScenarioKind::realistic, {1, 2, 3});
    EXPECT_GT(without, 1.2 * base) << base << " " << without;
}

TEST(ParticleFilter, ReweighsTheMovedParticlesAfterResampling) {
    // Step 6: after resampling and regularisation the weights are the current measurement's
    // likelihood of the moved particles, not 1/N.
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 1);
    ParticleFilter f;
    std::uint64_t seen = 0;
    for (std::size_t k = 0; k < sc.rows.size() && seen < 5; ++k) {
        const std::uint64_t before = f.state().resamples;
        f.update(sc.rows[k].sample);
        if (f.state().resamples == before) continue;
        ++seen;
        double lo = 1.0, hi = 0.0, sum = 0.0;
        for (int i = 0; i < f.particle_count(); ++i) {
            lo = std::min(lo, f.weight(i));
            hi = std::max(hi, f.weight(i));
            sum += f.weight(i);
        }
        EXPECT_NEAR(sum, 1.0, 1e-9);
        EXPECT_GT(hi, lo * (1.0 + 1e-6)) << k;  // not uniform
        EXPECT_LT(f.state().n_eff, f.particle_count());
    }
    EXPECT_EQ(seen, 5u);
}

TEST(ParticleFilter, NoMagnetometerWeighsTiltOnlyNoAccelerometerNothing) {
    const auto rows = testing::constant_rate(math::Quat::Identity(), math::Vec3(0, 0, 0.3), 100.0, 1.0);
    ParticleFilter f;
    f.update(rows[0].sample);
    f.update(rows[1].sample);
    const std::uint64_t rejected = f.state().rejected_measurements;
    const double yaw0 = math::to_euler_zyx(f.orientation()).yaw_rad;
    ImuSample s = rows[2].sample;
    s.flags = kImuNoMag;
    const double w0 = f.weight(0);
    f.update(s);
    EXPECT_EQ(f.state().rejected_measurements, rejected);
    EXPECT_NE(f.weight(0), w0);  // weighed (tilt)
    s = rows[3].sample;
    s.accel_m_s2 = {0, 0, 0};
    const double w1 = f.weight(0);
    f.update(s);
    EXPECT_EQ(f.state().rejected_measurements, rejected + 1);
    EXPECT_EQ(f.weight(0), w1);  // no measurement, no reweighting
    // The gyro still propagated: 2 steps of 0.3 rad/s about z.
    EXPECT_NEAR(math::to_euler_zyx(f.orientation()).yaw_rad - yaw0, 0.006, 0.001);
    s = rows[4].sample;
    s.gyro_rad_s = {std::nan(""), 0, 0};
    f.update(s);
    EXPECT_TRUE(f.orientation().coeffs().allFinite());
}

TEST(ParticleFilter, DisturbedFieldGatesTheHeading) {
    // The magnetic scenario turns the horizontal field by 39° for a while: the default
    // filter's detection rejects it, and the particle filter weighs tilt only meanwhile.
    for (const std::uint64_t seed : {1u, 2u}) {
        const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::magnetic, seed);
        ParticleFilter gated;
        ParticleFilterParams p;
        p.detect = false;
        ParticleFilter open(p);
        const testing::Rmse rg = testing::run(gated, sc.rows, 5.0);
        const testing::Rmse ro = testing::run(open, sc.rows, 5.0);
        EXPECT_GT(gated.state().heading_gated, 0u) << seed;
        EXPECT_EQ(open.state().heading_gated, 0u) << seed;
        EXPECT_LT(rg.heading_deg, 0.5 * ro.heading_deg) << seed << " " << rg.heading_deg << " " << ro.heading_deg;
    }
}

// A smooth rotation that never rests, sampled at rate_hz from sensors whose white noise has
// a fixed density (per-sample σ = density·√rate), with a constant gyro bias.
std::vector<sim::ScenarioRow> moving_with_bias(double rate_hz, double duration_s, const math::Vec3& bias_rad_s,
                                               std::uint64_t seed) {
    std::uint64_t x = seed * 0x9E3779B97F4A7C15ull + 1;
    const auto uniform = [&x] {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        return (static_cast<double>(x >> 11) + 0.5) * 0x1.0p-53;
    };
    const auto normal3 = [&](double sigma) {
        math::Vec3 v;
        for (int k = 0; k < 3; ++k)
            v[k] = sigma * std::sqrt(-2.0 * std::log(uniform())) * std::cos(2.0 * std::numbers::pi * uniform());
        return v;
    };
    const double root = std::sqrt(rate_hz);
    const auto w = [](double t) {
        return math::Vec3(0.6 * std::sin(0.7 * t), 0.5 * std::cos(0.45 * t), 0.3 + 0.5 * std::sin(0.3 * t + 1.0));
    };
    std::vector<sim::ScenarioRow> rows =
        testing::rotating(math::quat_from_rotvec(math::Vec3(0.3, -0.2, 1.0)), w, rate_hz, duration_s);
    for (sim::ScenarioRow& r : rows) {
        ImuSample& s = r.sample;
        s.gyro_rad_s = math::to_array(math::to_vec3(s.gyro_rad_s) + bias_rad_s + normal3(0.003 * root));
        s.accel_m_s2 = math::to_array(math::to_vec3(s.accel_m_s2) + normal3(0.01 * root));
        s.mag_ut = math::to_array(math::to_vec3(s.mag_ut) + normal3(0.1 * root));
    }
    return rows;
}

TEST(ParticleFilter, GyroBiasConvergesWithoutRest) {
    // A constant bias of about 1°/s per axis on a sensor that never rests: the bias state
    // is learned from the motion alone. Measured: see the printed figures.
    const math::Vec3 bias(0.02, -0.015, 0.012);
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
        const auto rows = moving_with_bias(100.0, 180.0, bias, seed);
        ParticleFilter f;
        double err_10s = 0.0, err_sum = 0.0;
        int n_last = 0;
        for (const sim::ScenarioRow& r : rows) {
            f.update(r.sample);
            const double t = static_cast<double>(r.sample.t_us) * 1e-6;
            const double e = (f.gyro_bias_rad_s() - bias).norm();
            if (std::abs(t - 10.0) < 1e-6) err_10s = e;
            if (t >= 150.0) {
                err_sum += e;
                ++n_last;
            }
        }
        const double err_end = err_sum / n_last;
        EXPECT_LT(err_end, 0.2 * bias.norm()) << seed << " " << err_10s << " " << err_end;
        EXPECT_LT(err_end, 0.5 * err_10s) << seed << " " << err_10s << " " << err_end;
    }
}

TEST(ParticleFilter, ParametersDoNotDependOnTheSampleRate) {
    // The same motion and sensor noise densities at 100 Hz and 400 Hz: with the noises as
    // densities the filter's error is about the same (with per-sample σ the 400 Hz run
    // would trust its measurements four times as much per second).
    const math::Vec3 bias(0.01, -0.01, 0.005);
    for (const std::uint64_t seed : {1u, 2u}) {
        ParticleFilter slow, fast;
        const testing::Rmse a = testing::run(slow, moving_with_bias(100.0, 90.0, bias, seed), 10.0);
        const testing::Rmse b = testing::run(fast, moving_with_bias(400.0, 90.0, bias, seed), 10.0);
        EXPECT_NEAR(a.total_deg, b.total_deg, 0.25 * std::max(a.total_deg, b.total_deg))
            << seed << " " << a.total_deg << " " << b.total_deg;
        EXPECT_LT((slow.gyro_bias_rad_s() - fast.gyro_bias_rad_s()).norm(), 0.3 * bias.norm()) << seed;
    }
}

TEST(ParticleFilter, WaitsForAUsableFirstMeasurement) {
    const auto rows =
        testing::constant_rate(math::quat_from_rotvec(math::Vec3(0, 0, 1.0)), math::Vec3::Zero(), 100.0, 0.1);
    ParticleFilter f;
    ImuSample s = rows[0].sample;
    s.accel_m_s2 = {0, 0, 0};
    f.update(s);
    EXPECT_FALSE(f.state().initialised);
    f.update(rows[1].sample);
    EXPECT_TRUE(f.state().initialised);
    EXPECT_LT(math::angle_rad(f.orientation() * rows[1].q_earth_sensor.conjugate()), 0.05);
}

TEST(ParticleFilter, UpdateDoesNotAllocate) {
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 1);
    const long c0 = g_allocations.load();
    { const ParticleFilter probe; }
    ASSERT_GT(g_allocations.load() - c0, 0) << "the allocation counter is not hooked";
    ParticleFilter f;
    f.update(sc.rows[0].sample);
    const long before = g_allocations.load();
    for (std::size_t k = 1; k < 3000; ++k)
        f.update(sc.rows[k].sample);
    EXPECT_EQ(g_allocations.load() - before, 0);
    EXPECT_GT(f.state().resamples, 0u);
}

TEST(ParticleFilter, ParticleCountIsClamped) {
    ParticleFilterParams p;
    p.particles = 0;
    EXPECT_EQ(ParticleFilter(p).particle_count(), 1);
    p.particles = 1024;
    EXPECT_EQ(ParticleFilter(p).particle_count(), 1024);
    EXPECT_EQ(ParticleFilter().name(), "pf");
}

}  // namespace
}  // namespace mocap::filter
