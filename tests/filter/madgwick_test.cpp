#include "filter/madgwick.hpp"

#include <gtest/gtest.h>

#include "seed_filter_fixture.hpp"
#include "sim/scenario.hpp"

namespace mocap::filter {
namespace {

using testing::kRadToDeg;

// A sensor held still at `truth` for duration_s (100 Hz, noiseless, dip 60°).
std::vector<sim::ScenarioRow> still(const math::Quat& truth, double duration_s) {
    return testing::constant_rate(truth, math::Vec3::Zero(), 100.0, duration_s);
}

TEST(Madgwick, FirstSampleGivesTheClosedFormAttitude) {
    const math::Quat truth = math::from_euler_zyx({0.3, -0.2, 2.0});
    MadgwickFilter f;
    f.update(still(truth, 0.0).front().sample);
    EXPECT_LT(math::angle_rad(f.orientation() * truth.conjugate()) * kRadToDeg, 1e-6);
}

TEST(Madgwick, StartsAtIdentityWhenAsked) {
    MadgwickParams p;
    p.init_from_first_sample = false;
    MadgwickFilter f(p);
    f.update(still(math::from_euler_zyx({0.3, -0.2, 2.0}), 0.0).front().sample);
    EXPECT_LT(math::angle_rad(f.orientation()), 1e-12);
}

TEST(Madgwick, ConvergesFromIdentityAtRest) {
    // beta = 0.1 rad/s turns the estimate by at most 0.1 rad/s: a 120° offset needs ~20 s;
    // after 60 s it is within 0.5°.
    const math::Quat truth = math::from_euler_zyx({0.4, 0.3, -2.0});
    MadgwickParams p;
    p.beta = 0.1;
    p.init_from_first_sample = false;
    MadgwickFilter f(p);
    EXPECT_LT(testing::run(f, still(truth, 60.0), 59.9).worst_deg, 0.5);
}

TEST(Madgwick, TracksNoiselessRotation) {
    const auto rows =
        testing::constant_rate(math::from_euler_zyx({0.2, 0.1, 0.5}), math::Vec3(0.3, -0.5, 0.8), 100.0, 20.0);
    MadgwickFilter f;
    // First-order integration of the published algorithm: small lag, no drift.
    EXPECT_LT(testing::run(f, rows, 0.0).worst_deg, 1.0);
}

TEST(Madgwick, WithoutMagnetometerOnlyInclinationIsCorrected) {
    // Accel-only fallback: a tilted sensor at rest, started level (ENU identity); the
    // inclination converges, the heading stays where the (zero) gyro left it.
    MadgwickParams p;
    p.beta = 0.1;
    p.init_from_first_sample = false;
    MadgwickFilter f(p);
    auto rows = still(math::from_euler_zyx({0.5, 0.0, 0.0}), 30.0);
    for (auto& r : rows)
        r.sample.flags = kImuNoMag;
    const testing::Rmse r = testing::run(f, rows, 29.9);
    EXPECT_LT(r.inclination_deg, 0.2);
    EXPECT_LT(r.heading_deg, 1.0);
}

TEST(Madgwick, RealisticScenarioAccuracy) {
    // Measured 1.1–1.4° total over seeds 1–5; tolerance leaves room, not a free pass.
    const sim::Scenario sc = sim::make_scenario(sim::ScenarioKind::realistic, 1);
    MadgwickFilter f;
    const testing::Rmse r = testing::run(f, sc.rows, 5.0);
    EXPECT_LT(r.total_deg, 2.5);
    EXPECT_LT(r.inclination_deg, 1.5);
}

TEST(Madgwick, ResetAndGaps) {
    MadgwickFilter f;
    ImuSample s = still(math::from_euler_zyx({0.1, 0.2, 0.3}), 0.0).front().sample;
    for (const std::int64_t t_us : {0, 10000, 10000, 5000000}) {  // repeat, then a 5 s jump
        s.t_us = t_us;
        f.update(s);
    }
    EXPECT_EQ(f.gaps(), 2u);
    f.reset();
    EXPECT_EQ(f.gaps(), 0u);
    EXPECT_FALSE(f.state().initialised);
    EXPECT_LT(math::angle_rad(f.orientation()), 1e-12);  // ENU identity
}

}  // namespace
}  // namespace mocap::filter
