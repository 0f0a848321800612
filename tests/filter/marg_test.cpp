#include "filter/marg.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "seed_filter_fixture.hpp"

namespace mocap::filter {
namespace {

// One noiseless sample of a sensor held still at `truth` (48 µT at 60° dip).
ImuSample still_sample(const math::Quat& truth) {
    return testing::constant_rate(truth, math::Vec3::Zero(), 100.0, 0.0).front().sample;
}

TEST(Marg, ClosedFormAttitudeFromAccelAndMag) {
    const math::Quat truth = math::from_euler_zyx({0.3, -0.5, 2.5});
    const ImuSample s = still_sample(truth);
    const math::Quat q = attitude_from_accel_mag(math::to_vec3(s.accel_m_s2), math::to_vec3(s.mag_ut), true);
    EXPECT_LT(math::angle_rad(q * truth.conjugate()), 1e-9);
    // Without the magnetometer: same inclination, reached by a rotation about a horizontal
    // axis (no z component).
    const math::Quat q6 = attitude_from_accel_mag(math::to_vec3(s.accel_m_s2), math::Vec3::Zero(), false);
    EXPECT_LT(math::error_inclination_rad(q6 * truth.conjugate()), 1e-9);
    EXPECT_LT(std::abs(q6.z()), 1e-12);
    // Upside down.
    const math::Quat flipped = attitude_from_accel_mag(math::Vec3(0, 0, -9.81), math::Vec3::Zero(), false);
    EXPECT_LT(std::abs(math::rotate(flipped, math::Vec3(0, 0, -1)).z() - 1.0), 1e-12);
}

TEST(Marg, MagnetometerParallelToGravityGivesZeroHeading) {
    // TRIAD has no heading to take from a field along the vertical: the tilt alone, as without it.
    const math::Vec3 accel(0.0, 0.0, 9.81);
    const math::Quat q = attitude_from_accel_mag(accel, math::Vec3(0.0, 0.0, -40.0), true);
    EXPECT_LT(math::angle_rad(q), 1e-12);
}

TEST(Marg, TiltToVerticalTakesTheVectorOntoEarthZWithoutTurningAboutIt) {
    const math::Vec3 u = math::Vec3(0.3, -0.4, 0.8).normalized();
    const math::Quat q = tilt_to_vertical(u);
    EXPECT_LT((math::rotate(q, u) - math::Vec3::UnitZ()).norm(), 1e-12);
    EXPECT_LT(std::abs(q.z()), 1e-15);
    EXPECT_LT(math::angle_rad(tilt_to_vertical(math::Vec3::UnitZ())), 1e-12);
    const math::Quat down = tilt_to_vertical(-math::Vec3::UnitZ());
    EXPECT_LT((math::rotate(down, -math::Vec3::UnitZ()) - math::Vec3::UnitZ()).norm(), 1e-12);
}

TEST(Marg, ReadingIsUsableOnlyWhenPresentNonZeroAndFinite) {
    ImuSample s = still_sample(math::Quat::Identity());
    MargReading r = read_marg(s);
    EXPECT_TRUE(r.accel_ok);
    EXPECT_TRUE(r.mag_ok);
    EXPECT_EQ(r.accel_m_s2, math::to_vec3(s.accel_m_s2));
    EXPECT_EQ(r.mag_ut, math::to_vec3(s.mag_ut));

    ImuSample no_mag = s;
    no_mag.flags |= kImuNoMag;
    EXPECT_FALSE(read_marg(no_mag).mag_ok);
    EXPECT_TRUE(read_marg(no_mag).accel_ok);

    ImuSample zero = s;
    zero.accel_m_s2 = {0.0, 0.0, 0.0};
    zero.mag_ut = {0.0, 0.0, 0.0};
    r = read_marg(zero);
    EXPECT_FALSE(r.accel_ok);
    EXPECT_FALSE(r.mag_ok);

    ImuSample bad = s;
    bad.accel_m_s2[1] = std::numeric_limits<double>::quiet_NaN();
    bad.mag_ut[2] = std::numeric_limits<double>::infinity();
    r = read_marg(bad);
    EXPECT_FALSE(r.accel_ok);
    EXPECT_FALSE(r.mag_ok);
}

}  // namespace
}  // namespace mocap::filter
