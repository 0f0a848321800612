#include "filter/csmo.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "seed_filter_fixture.hpp"

namespace mocap::filter {
namespace {

using testing::kRadToDeg;

CsmoParams starting_at(const math::Quat& q0) {
    CsmoParams p;
    p.q0w = q0.w();
    p.q0x = q0.x();
    p.q0y = q0.y();
    p.q0z = q0.z();
    return p;
}

// Seconds until the error stays below limit_deg for the rest of the run.
double settle_time_s(Csmo& f, const std::vector<sim::ScenarioRow>& rows, double limit_deg) {
    double last = 0.0;
    for (const sim::ScenarioRow& r : rows) {
        f.update(r.sample);
        if (math::angle_rad(f.orientation() * r.q_earth_sensor.conjugate()) * kRadToDeg > limit_deg)
            last = static_cast<double>(r.sample.t_us) * 1e-6;
    }
    return last;
}

TEST(Csmo, DefaultsAreThePapersGains) {
    const CsmoParams p;
    EXPECT_EQ(p.k1, 1e-3);
    EXPECT_EQ(p.k3, 1e-3);
    EXPECT_EQ(p.k4, 9e-4);
    EXPECT_EQ(p.k6, 9e-4);
    EXPECT_EQ(p.rho, 3e-4);
    EXPECT_EQ(p.gain_rate_hz, 100.0);
    Csmo f;
    EXPECT_EQ(f.name(), "csmo");
    EXPECT_LT(math::angle_rad(f.orientation()), 1e-15);
}

TEST(Csmo, TracksNoiselessFouratiMotionWithinTheChatterBand) {
    sim::ScenarioOptions o;
    o.noise_scale = 0.0;
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::fourati, 1, o);
    for (const double dip : {60.0, std::nan("")}) {
        CsmoParams p = starting_at(testing::fourati_start_truth());
        p.dip_deg = dip;
        Csmo f(p);
        const testing::Rmse r = testing::run(f, sc.rows, 0.0);
        // The boundary-layer loop gain k/ρ > 2 makes the estimate chatter by ~±2k rad.
        EXPECT_LT(r.worst_deg, 0.35) << dip;
        EXPECT_LT(r.total_deg, 0.15) << dip;
    }
}

TEST(Csmo, ConvergesFromThePapersFarOffStartOnNoiselessData) {
    sim::ScenarioOptions o;
    o.noise_scale = 0.0;
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::fourati, 2, o);
    const math::Quat start = testing::fourati_paper_initial_estimate();
    EXPECT_GT(math::angle_rad(start * testing::fourati_start_truth().conjugate()) * kRadToDeg, 150.0);
    Csmo f(starting_at(start));
    // The saturated switching term turns ≤ 0.2 rad/s per axis: 155° takes ~10-20 s.
    const double t = settle_time_s(f, sc.rows, 1.0);
    EXPECT_GT(t, 3.0);
    EXPECT_LT(t, 30.0);
}

TEST(Csmo, FouratiScenarioAccuracyWithThePapersGains) {
    // Table II noise (σ = 0.4 on every sensor, 0.4 G on a 0.5 G field). With each sample's
    // own dip (default) the magnetometer only sets heading. Measured over seeds 1-5:
    // inclination 2.8-3.8°, heading 5.0-6.7°, total 6.0-7.2°. Table I's path passes within
    // 0.5° of pitch ±90°, where the Euler split is ill-conditioned: roll 3.6-7.7°, pitch
    // 2.0-2.6°, yaw 6.9-8.3°.
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
        const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::fourati, seed);
        Csmo f(starting_at(testing::fourati_start_truth()));
        const testing::Rmse r = testing::run(f, sc.rows, 5.0);
        EXPECT_LT(r.inclination_deg, 4.5) << seed;
        EXPECT_LT(r.heading_deg, 8.0) << seed;
        EXPECT_LT(r.total_deg, 8.5) << seed;
        EXPECT_LT(r.roll_deg, 9.5) << seed;
        EXPECT_LT(r.pitch_deg, 3.5) << seed;
        EXPECT_LT(r.yaw_deg, 10.0) << seed;
    }
}

TEST(Csmo, FixedDipReferenceIsBiasedByTheNoisyField) {
    // The paper's LMA fits a 60° reference to a field whose noise (80% of its norm) makes
    // the measured dip ~34° on average, so q_m is tilted ~10° about east every sample: the
    // fixed-dip (paper-exact) CSMO has 1.6-3.3 times the tilt error of the default (seeds 1-5).
    for (const std::uint64_t seed : {1u, 2u, 3u}) {
        const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::fourati, seed);
        CsmoParams p = starting_at(testing::fourati_start_truth());
        Csmo auto_dip(p);
        p.dip_deg = 60.0;
        Csmo fixed_dip(p);
        const testing::Rmse a = testing::run(auto_dip, sc.rows, 5.0);
        const testing::Rmse b = testing::run(fixed_dip, sc.rows, 5.0);
        EXPECT_GT(b.inclination_deg, 1.4 * a.inclination_deg) << seed;
    }
}

TEST(Csmo, GainsScaleWithTheSampleRate) {
    // From the same 20° error, the correction per second is the same at 50, 100 and 200 Hz.
    const math::Quat truth0 = math::quat_from_rotvec(math::Vec3(0.3, -0.4, 1.2));
    const math::Quat start = truth0 * math::quat_from_rotvec(math::Vec3(0.2, 0.25, -0.1));
    const math::Vec3 w(0.2, -0.1, 0.3);
    double t100 = 0;
    for (const double hz : {100.0, 50.0, 200.0}) {
        Csmo f(starting_at(start));
        const double t = settle_time_s(f, testing::constant_rate(truth0, w, hz, 40.0), 1.0);
        if (hz == 100.0) {
            t100 = t;
            EXPECT_GT(t, 1.0);
        } else {
            EXPECT_NEAR(t, t100, 0.15 * t100) << hz;
        }
    }
}

TEST(Csmo, InitialisesFromTheMeasurementWhenAsked) {
    const math::Quat truth0 = math::quat_from_rotvec(math::Vec3(-0.5, 0.4, 2.5));
    const auto rows = testing::constant_rate(truth0, math::Vec3(0, 0, 0.1), 100.0, 1.0);
    CsmoParams p;
    p.init_from_measurement = true;
    Csmo f(p);
    f.update(rows[0].sample);
    EXPECT_LT(math::angle_rad(f.orientation() * truth0.conjugate()), 1e-6);
}

TEST(Csmo, RejectsUnusableMeasurementsAndGapsWithoutNaN) {
    const auto rows = testing::constant_rate(math::Quat::Identity(), math::Vec3(0, 0, 0.5), 100.0, 1.0);
    Csmo f;
    f.update(rows[0].sample);
    ImuSample s = rows[1].sample;
    s.accel_m_s2 = {0, 0, 0};  // free fall
    f.update(s);
    s = rows[2].sample;
    s.flags = kImuNoMag;
    f.update(s);
    s = rows[3].sample;
    s.mag_ut = {0, 0, 40.0};  // parallel to gravity
    f.update(s);
    EXPECT_EQ(f.state().rejected_measurements, 3u);
    // Gyro-only propagation still happened: 3 samples at 0.5 rad/s about z.
    EXPECT_NEAR(math::to_euler_zyx(f.orientation()).yaw_rad, 0.015, 1e-3);
    s = rows[3].sample;  // time going back: a gap, no propagation
    f.update(s);
    s = rows[50].sample;  // 0.47 s later: still within max_step_s
    f.update(s);
    s.t_us += 2'000'000;  // 2 s jump: a gap
    f.update(s);
    EXPECT_EQ(f.gaps(), 2u);
    s.gyro_rad_s = {std::nan(""), 0, 0};
    s.t_us += 10'000;
    f.update(s);
    EXPECT_TRUE(f.orientation().coeffs().allFinite());
    f.reset();
    EXPECT_EQ(f.gaps(), 0u);
    EXPECT_EQ(f.state().rejected_measurements, 0u);
    EXPECT_LT(math::angle_rad(f.orientation()), 1e-15);
}

TEST(Csmo, ZeroNormInitialEstimateFallsBackToIdentity) {
    CsmoParams p;
    p.q0w = 0.0;
    Csmo f(p);
    EXPECT_LT(math::angle_rad(f.orientation()), 1e-15);
}

}  // namespace
}  // namespace mocap::filter
