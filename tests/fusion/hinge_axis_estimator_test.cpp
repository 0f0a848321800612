// The hinge axis estimator on synthetic hinge motion with known axes: noiseless, then with
// MEMS gyro noise and bias residue; the relative sign of the two axes from the 6D frames.
#include "fusion/hinge_axis_estimator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace mocap::fusion {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Quat axis_angle(const Vec3& axis, double a) {
    return Quat(Eigen::AngleAxisd(a, axis.normalized()));
}
Quat rz(double a) {
    return axis_angle(Vec3::UnitZ(), a);
}

struct HingeCase {
    Vec3 jp, jc;
    double noise_rad_s = 0.0;
    double bias_rad_s = 0.0;
    double heading_child = 0.0;  // the child's 6D frame is turned by this about the vertical
};

/// Feeds 60 s at 100 Hz of a hinge moving while its parent turns about all axes; returns the
/// estimator.
HingeAxisEstimator feed(const HingeCase& c, double duration_s = 60.0) {
    HingeAxisEstimator est;
    const Quat mount = Quat::FromTwoVectors(c.jc, c.jp);
    std::mt19937 rng(7);
    std::normal_distribution<double> n(0.0, 1.0);
    const Vec3 bias_p = c.bias_rad_s * Vec3(1, -1, 0.5), bias_c = c.bias_rad_s * Vec3(-0.5, 1, 1);
    const double dt = 0.01;
    const auto parent = [](double t) {
        return rz(0.8 * std::sin(0.31 * t)) * axis_angle(Vec3(1, 0, 0), 0.6 * std::sin(0.73 * t)) *
               axis_angle(Vec3(0, 1, 0), 0.5 * std::sin(0.57 * t + 1.0));
    };
    const auto child = [&](double t, const Quat& qp) {
        return qp * mount * axis_angle(c.jc, 1.1 * std::sin(1.3 * t) + 0.4 * std::sin(0.37 * t));
    };
    Quat pp = parent(0), pc = child(0, pp);
    for (int k = 1; k * dt <= duration_s; ++k) {
        const double t = k * dt;
        const Quat qp = parent(t), qc = child(t, qp);
        const Vec3 noise_p(n(rng), n(rng), n(rng)), noise_c(n(rng), n(rng), n(rng));
        const Vec3 wp = math::rotvec_from_quat(pp.conjugate() * qp) / dt + bias_p + c.noise_rad_s * noise_p;
        const Vec3 wc = math::rotvec_from_quat(pc.conjugate() * qc) / dt + bias_c + c.noise_rad_s * noise_c;
        est.add(static_cast<std::int64_t>(std::llround(t * 1e6)), wp, wc, qp, rz(c.heading_child) * qc);
        pp = qp;
        pc = qc;
    }
    return est;
}

double angle_deg(const Vec3& a, const Vec3& b) {
    return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) / kDeg;
}

/// The estimate equals the truth up to flipping both axes together (the same hinge).
void expect_axes(const HingeAxisEstimator& est, const HingeCase& c, double tol_deg) {
    ASSERT_TRUE(est.ready());
    const double s = est.axis_parent().dot(c.jp) >= 0.0 ? 1.0 : -1.0;
    EXPECT_LT(angle_deg(s * est.axis_parent(), c.jp), tol_deg);
    EXPECT_LT(angle_deg(s * est.axis_child(), c.jc), tol_deg) << "child axis wrong or its sign not the parent's";
}

TEST(HingeAxisEstimator, FindsBothAxesOnNoiselessMotion) {
    HingeCase c{Vec3(0.2, 0.9, -0.3).normalized(), Vec3(-0.7, 0.1, 0.7).normalized()};
    expect_axes(feed(c), c, 0.2);
}

TEST(HingeAxisEstimator, FindsThemWithMemsNoiseAndBiasResidue) {
    // 0.3 °/s white noise per sample and 0.2 °/s of bias left: about a degree.
    HingeCase c{Vec3(0.9, -0.1, 0.4).normalized(), Vec3(0.1, 0.2, -0.97).normalized(), 0.3 * kDeg, 0.2 * kDeg};
    expect_axes(feed(c), c, 1.5);
}

TEST(HingeAxisEstimator, TheChildsSignFollowsTheParentsWhateverTheHeadingOffset) {
    // The 6D frames 150° apart: the sign test uses only heading-free quantities.
    HingeCase c{Vec3(0, 0, 1), Vec3(1, 0, 0), 0.0, 0.0, 150.0 * kDeg};
    expect_axes(feed(c), c, 0.5);
}

TEST(HingeAxisEstimator, NotReadyWithoutMotion) {
    HingeAxisEstimator est;
    for (int k = 0; k < 6000; ++k) {
        est.add(k * 10'000, Vec3(0.001, 0, 0), Vec3(0, 0.001, 0), Quat::Identity(), Quat::Identity());
    }
    EXPECT_FALSE(est.ready());
    EXPECT_EQ(est.samples(), 0u);
}

// A joint that does not bend: both segments turn together, any axis pair related by the fixed
// relative rotation fits, so the motion does not identify the axes: never ready.
TEST(HingeAxisEstimator, NotReadyWhenTheJointDoesNotMove) {
    HingeAxisEstimator est;
    const double dt = 0.01;
    const auto q = [](double t) {
        return rz(1.5 * std::sin(0.7 * t)) * axis_angle(Vec3(1, 0, 0), 0.9 * std::sin(1.3 * t));
    };
    const Quat rel = axis_angle(Vec3(0.3, 0.4, 0.5), 1.0);
    Quat prev = q(0);
    for (int k = 1; k < 6000; ++k) {
        const Quat now = q(k * dt);
        const Vec3 w = math::rotvec_from_quat(prev.conjugate() * now) / dt;
        est.add(k * 10'000, w, math::rotate(rel.conjugate(), w), now, now * rel);
        prev = now;
    }
    EXPECT_GT(est.samples(), 100u);
    EXPECT_FALSE(est.ready());
}

}  // namespace
}  // namespace mocap::fusion
