// The vector-pair constraint of joint_constraints.hpp on exact vectors: what it measures of δ,
// when it says nothing, and when a known δ shows a learned hinge axis's sign is wrong.
#include "fusion/joint_constraints.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace mocap::fusion {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;  // not kDeg: shares a unity batch with chain_estimator_test.cpp

TEST(PairMeasurement, MeasuresTheHeadingThatTurnsTheChildsVectorOntoTheParents) {
    const Vec3 b = Vec3(0.6, -0.3, 0.5).normalized();
    const double delta = 40.0 * kRadPerDeg;
    const Vec3 a = rotate_z(delta, b);
    const HeadingMeasurement m = pair_measurement(a, b, 25.0 * kRadPerDeg, 0.03, 0.2);
    ASSERT_TRUE(m.ok);
    EXPECT_NEAR(m.residual_rad / kRadPerDeg, 15.0, 1e-9);
    EXPECT_GT(m.var_rad2, 0.0);
    // A nearly vertical vector has no heading to compare.
    EXPECT_FALSE(pair_measurement(Vec3(0.05, 0.0, 1.0), Vec3(0.0, 0.05, 1.0), 0.0, 0.03, 0.2).ok);
}

// A knee's axis learned with the child's sign flipped says δ + 180°: a δ known from agreeing
// fields shows it, and the consistent pair, a vertical one, or a δ off by less than a right
// angle (an axis that is only off) does not count as flipped.
TEST(PairContradicts, ShowsAFlippedChildAxisAgainstAKnownHeading) {
    const Vec3 axis_c = Vec3(0.9, 0.3, 0.1).normalized();
    const double delta = -70.0 * kRadPerDeg;
    const Vec3 axis_p = rotate_z(delta, axis_c);
    EXPECT_FALSE(pair_contradicts(axis_p, axis_c, delta, 0.2));
    EXPECT_TRUE(pair_contradicts(axis_p, -axis_c, delta, 0.2));
    EXPECT_TRUE(pair_contradicts(-axis_p, axis_c, delta + 10.0 * kRadPerDeg, 0.2));
    EXPECT_FALSE(pair_contradicts(axis_p, axis_c, delta + 80.0 * kRadPerDeg, 0.2));
    EXPECT_FALSE(pair_contradicts(Vec3(0.05, 0.0, 1.0), -Vec3(0.05, 0.0, 1.0), 0.0, 0.2));
}

}  // namespace
}  // namespace mocap::fusion
