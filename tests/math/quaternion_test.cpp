#include "math/quaternion.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace mocap::math {
namespace {

constexpr double kPi = std::numbers::pi;

Quat random_quat(std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

double qdist(const Quat& a, const Quat& b) {
    return angle_rad(a * b.conjugate());
}

TEST(Quaternion, HamiltonProductMatchesHandExpansion) {
    const Quat a(1, 2, 3, 4), b(5, 6, 7, 8);
    const Quat c = mul(a, b);
    // (1+2i+3j+4k)(5+6i+7j+8k) = -60 + 12i + 30j + 24k
    EXPECT_DOUBLE_EQ(c.w(), -60);
    EXPECT_DOUBLE_EQ(c.x(), 12);
    EXPECT_DOUBLE_EQ(c.y(), 30);
    EXPECT_DOUBLE_EQ(c.z(), 24);
}

TEST(Quaternion, RotateIsSandwichProduct) {
    std::mt19937 rng(1);
    for (int i = 0; i < 100; ++i) {
        const Quat q = random_quat(rng);
        const Vec3 v(1.0, -2.0, 0.5);
        const Quat p = q * Quat(0, v.x(), v.y(), v.z()) * conj(q);
        EXPECT_NEAR((rotate(q, v) - p.vec()).norm(), 0.0, 1e-12);
    }
    // 90° about z maps east to north.
    const Quat qz = quat_from_rotvec(Vec3(0, 0, kPi / 2));
    EXPECT_NEAR((rotate(qz, Vec3::UnitX()) - Vec3::UnitY()).norm(), 0.0, 1e-12);
}

TEST(Quaternion, ExpLogRoundTrip) {
    std::mt19937 rng(2);
    for (int i = 0; i < 200; ++i) {
        const Quat q = canonical(random_quat(rng));
        const Quat back = quat_exp(quat_log(q));
        EXPECT_NEAR(qdist(q, back), 0.0, 1e-9);
        EXPECT_NEAR(quat_from_rotvec(rotvec_from_quat(q)).coeffs().dot(q.coeffs()), 1.0, 1e-12);
    }
    EXPECT_NEAR(quat_exp(Vec3::Zero()).w(), 1.0, 0.0);
    EXPECT_NEAR(rotvec_from_quat(Quat::Identity()).norm(), 0.0, 0.0);
    // 180° rotation keeps its angle.
    EXPECT_NEAR(rotvec_from_quat(Quat(0, 1, 0, 0)).norm(), kPi, 1e-12);
}

TEST(Quaternion, SlerpEndpointsMidpointAndShortestArc) {
    const Quat a = Quat::Identity();
    const Quat b = quat_from_rotvec(Vec3(0, 0, 1.0));
    EXPECT_NEAR(qdist(slerp(a, b, 0.0), a), 0.0, 1e-12);
    EXPECT_NEAR(qdist(slerp(a, b, 1.0), b), 0.0, 1e-12);
    EXPECT_NEAR(qdist(slerp(a, b, 0.5), quat_from_rotvec(Vec3(0, 0, 0.5))), 0.0, 1e-12);
    // -b is the same rotation: slerp must take the short way, not the 2π-1 rad way.
    Quat nb = b;
    nb.coeffs() = -nb.coeffs();
    EXPECT_NEAR(angle_rad(slerp(a, nb, 0.5)), 0.5, 1e-12);
    // Nearly equal inputs use the normalised-lerp branch and stay unit.
    const Quat c = quat_from_rotvec(Vec3(0, 0, 1e-6));
    EXPECT_NEAR(slerp(a, c, 0.3).norm(), 1.0, 1e-15);
}

TEST(Quaternion, RotationMatrixRoundTrip) {
    std::mt19937 rng(3);
    for (int i = 0; i < 200; ++i) {
        const Quat q = random_quat(rng);
        const Mat3 r = to_rotation_matrix(q);
        EXPECT_NEAR((r * r.transpose() - Mat3::Identity()).norm(), 0.0, 1e-12);
        EXPECT_NEAR(qdist(from_rotation_matrix(r), q), 0.0, 1e-9);
        const Vec3 v(0.3, -0.7, 2.0);
        EXPECT_NEAR((r * v - rotate(q, v)).norm(), 0.0, 1e-12);
    }
}

TEST(Quaternion, EulerZyxRoundTripAndAxes) {
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < 200; ++i) {
        const EulerZyx e{u(rng) * kPi, u(rng) * kPi / 2 * 0.99, u(rng) * kPi};
        const EulerZyx b = to_euler_zyx(from_euler_zyx(e));
        EXPECT_NEAR(wrap_pi(b.roll_rad - e.roll_rad), 0.0, 1e-9);
        EXPECT_NEAR(b.pitch_rad - e.pitch_rad, 0.0, 1e-9);
        EXPECT_NEAR(wrap_pi(b.yaw_rad - e.yaw_rad), 0.0, 1e-9);
    }
    const EulerZyx yaw_only = to_euler_zyx(quat_from_rotvec(Vec3(0, 0, 0.4)));
    EXPECT_NEAR(yaw_only.yaw_rad, 0.4, 1e-12);
    EXPECT_NEAR(yaw_only.roll_rad, 0.0, 1e-12);
    const EulerZyx roll_only = to_euler_zyx(quat_from_rotvec(Vec3(-0.3, 0, 0)));
    EXPECT_NEAR(roll_only.roll_rad, -0.3, 1e-12);
}

TEST(Quaternion, BroadErrorMetricsSplitHeadingAndInclination) {
    const Quat yaw = quat_from_rotvec(Vec3(0, 0, 0.2));
    EXPECT_NEAR(error_total_rad(yaw), 0.2, 1e-12);
    EXPECT_NEAR(error_heading_rad(yaw), 0.2, 1e-12);
    EXPECT_NEAR(error_inclination_rad(yaw), 0.0, 1e-7);
    const Quat tilt = quat_from_rotvec(Vec3(0.1, 0, 0));
    EXPECT_NEAR(error_inclination_rad(tilt), 0.1, 1e-12);
    EXPECT_NEAR(error_heading_rad(tilt), 0.0, 1e-12);
    // Sign of the quaternion does not matter.
    Quat neg = yaw;
    neg.coeffs() = -neg.coeffs();
    EXPECT_NEAR(error_total_rad(neg), 0.2, 1e-12);
    EXPECT_NEAR(error_heading_rad(neg), 0.2, 1e-12);
}

TEST(Quaternion, EnuNedConversionSwapsAxes) {
    const Quat q = q_enu_ned();
    EXPECT_NEAR((rotate(q, Vec3(1, 0, 0)) - Vec3(0, 1, 0)).norm(), 0.0, 1e-12);   // north
    EXPECT_NEAR((rotate(q, Vec3(0, 1, 0)) - Vec3(1, 0, 0)).norm(), 0.0, 1e-12);   // east
    EXPECT_NEAR((rotate(q, Vec3(0, 0, 1)) - Vec3(0, 0, -1)).norm(), 0.0, 1e-12);  // down
    EXPECT_NEAR(angle_rad(q * q), 0.0, 1e-12);                                    // self-inverse
}

TEST(Quaternion, WrapPiAndSkew) {
    EXPECT_NEAR(wrap_pi(3 * kPi), kPi, 1e-12);
    EXPECT_NEAR(wrap_pi(-kPi / 2), -kPi / 2, 1e-12);
    EXPECT_NEAR(wrap_pi(2 * kPi + 0.1), 0.1, 1e-12);
    const Vec3 a(1, 2, 3), b(-4, 5, 0.5);
    EXPECT_NEAR((skew(a) * b - a.cross(b)).norm(), 0.0, 1e-12);
}

}  // namespace
}  // namespace mocap::math
