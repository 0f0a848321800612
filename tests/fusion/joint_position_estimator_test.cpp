// The joint centre estimator on synthetic motion of two segments joined at one point (a ball
// joint), with the kinematics written out: the centre's path, both orientations, and each
// sensor's specific force from the second derivative of its own position.
#include "fusion/joint_position_estimator.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

namespace mocap::fusion {
namespace {

using math::Quat;

Quat axis_angle(const Vec3& axis, double a) {
    return Quat(Eigen::AngleAxisd(a, axis.normalized()));
}

struct Motion {
    std::function<Quat(double)> q_p, q_c;
    std::function<Vec3(double)> centre;
    Vec3 r_p, r_c;  // centre from each sensor, sensor frames
    Vec3 sensor(bool parent, double t) const {
        const Quat q = parent ? q_p(t) : q_c(t);
        return centre(t) - math::rotate(q, parent ? r_p : r_c);
    }
    Vec3 specific_force(bool parent, double t) const {
        const double h = 1e-3;
        const Vec3 a = (sensor(parent, t + h) - 2.0 * sensor(parent, t) + sensor(parent, t - h)) / (h * h);
        return math::rotate((parent ? q_p(t) : q_c(t)).conjugate(), a + Vec3(0, 0, 9.81));
    }
    Vec3 rate(bool parent, double t) const {
        const double h = 1e-4;
        const auto& q = parent ? q_p : q_c;
        return math::rotvec_from_quat(q(t - h).conjugate() * q(t + h)) / (2.0 * h);
    }
    Vec3 rate_dot(bool parent, double t) const {
        const double h = 1e-3;
        return (rate(parent, t + h) - rate(parent, t - h)) / (2.0 * h);
    }
};

Motion ball_joint() {
    Motion m;
    m.q_p = [](double t) {
        return axis_angle(Vec3::UnitZ(), 1.2 * std::sin(0.5 * t)) *
               axis_angle(Vec3(1, 0.2, 0), 0.8 * std::sin(1.1 * t)) *
               axis_angle(Vec3::UnitY(), 0.6 * std::sin(0.8 * t + 2.0));
    };
    m.q_c = [m](double t) {
        return m.q_p(t) * axis_angle(Vec3(0.3, 1, 0.2), 0.9 * std::sin(1.7 * t)) *
               axis_angle(Vec3(0, 0.1, 1), 0.7 * std::sin(1.3 * t + 1.0));
    };
    m.centre = [](double t) {
        return Vec3(0.3 * std::sin(0.9 * t), 0.2 * std::cos(0.6 * t), 1.0 + 0.1 * std::sin(1.4 * t));
    };
    m.r_p = Vec3(0.12, -0.05, 0.03);
    m.r_c = Vec3(-0.02, 0.15, 0.04);
    return m;
}

TEST(JointPositionEstimator, FindsTheCentreOfABallJoint) {
    const Motion m = ball_joint();
    JointPositionEstimator est;
    for (int k = 0; k < 6000; ++k) {
        const double t = 0.01 * k + 0.1;
        est.add(static_cast<std::int64_t>(std::llround(t * 1e6)), m.rate(true, t), m.rate_dot(true, t),
                m.specific_force(true, t), m.rate(false, t), m.rate_dot(false, t), m.specific_force(false, t));
    }
    ASSERT_TRUE(est.ready());
    EXPECT_LT((est.r_parent() - m.r_p).norm(), 0.005) << est.r_parent().transpose();
    EXPECT_LT((est.r_child() - m.r_c).norm(), 0.005) << est.r_child().transpose();
}

// The live chain gets its solutions one pass per step (no step pays for a whole solve): spread
// over the steps, a solve gives exactly what it gives at once on the same samples.
TEST(JointPositionEstimator, ASolveSpreadOverStepsGivesTheSolutionOfOneSolve) {
    const Motion m = ball_joint();
    JointPositionEstimator collected;
    for (int k = 0; k < 3000; ++k) {
        const double t = 0.01 * k + 0.1;
        collected.add(static_cast<std::int64_t>(std::llround(t * 1e6)), m.rate(true, t), m.rate_dot(true, t),
                      m.specific_force(true, t), m.rate(false, t), m.rate_dot(false, t), m.specific_force(false, t),
                      false);
    }
    JointPositionEstimator at_once = collected;
    ASSERT_TRUE(at_once.solve());
    ASSERT_TRUE(at_once.ready());
    // Steps that add no sample (nothing turns): each does one pass of the solve.
    JointPositionEstimator spread = collected;
    int steps = 0;
    for (; steps < 200 && !spread.take_solution(); ++steps) {
        EXPECT_TRUE(spread.add(40'000'000 + steps * 10'000, Vec3::Zero(), Vec3::Zero(), Vec3(0, 0, 9.81), Vec3::Zero(),
                               Vec3::Zero(), Vec3(0, 0, 9.81)));
    }
    EXPECT_GT(steps, 4) << "a solve is more than a few passes";
    EXPECT_LT(steps, 200) << "the solve never finished";
    ASSERT_TRUE(spread.ready());
    EXPECT_LT((spread.r_parent() - at_once.r_parent()).norm(), 1e-12);
    EXPECT_LT((spread.r_child() - at_once.r_child()).norm(), 1e-12);
    EXPECT_LT((spread.r_parent() - m.r_p).norm(), 0.005);
    // The next step has nothing to do until the next solve is due.
    EXPECT_FALSE(spread.add(40'000'000 + steps * 10'000, Vec3::Zero(), Vec3::Zero(), Vec3(0, 0, 9.81), Vec3::Zero(),
                            Vec3::Zero(), Vec3(0, 0, 9.81)));
}

// A parent that only ever turns about one axis: its centre's position along that axis changes
// nothing the sensors see, so the estimate is not trusted.
TEST(JointPositionEstimator, NotReadyWhenThePositionIsUnobservable) {
    Motion m = ball_joint();
    m.q_p = [](double t) { return axis_angle(Vec3::UnitZ(), 1.5 * std::sin(0.9 * t)); };
    m.q_c = [m](double t) { return m.q_p(t) * axis_angle(Vec3(0.3, 1, 0.2), 0.9 * std::sin(1.7 * t)); };
    m.centre = [](double) { return Vec3(0, 0, 1); };
    JointPositionEstimator est;
    for (int k = 0; k < 6000; ++k) {
        const double t = 0.01 * k + 0.1;
        est.add(static_cast<std::int64_t>(std::llround(t * 1e6)), m.rate(true, t), m.rate_dot(true, t),
                m.specific_force(true, t), m.rate(false, t), m.rate_dot(false, t), m.specific_force(false, t));
    }
    EXPECT_GT(est.samples(), 100u);
    EXPECT_FALSE(est.ready());
}

TEST(JointPositionEstimator, NotReadyWhenNothingTurns) {
    JointPositionEstimator est;
    for (int k = 0; k < 6000; ++k) {
        est.add(k * 10'000, Vec3::Zero(), Vec3::Zero(), Vec3(0, 0, 9.81), Vec3::Zero(), Vec3::Zero(), Vec3(0, 9.81, 0));
    }
    EXPECT_FALSE(est.ready());
    EXPECT_EQ(est.samples(), 0u);
}

TEST(JointPositionEstimator, GammaMovesTheSpecificForceToAnotherPoint) {
    // A sensor turning at a constant 2 rad/s about z: a point 0.5 m out along x has the
    // centripetal 2 m/s² towards the axis more specific force... towards the sensor: −x·ω²·r.
    const Eigen::Matrix3d g = gamma_matrix(Vec3(0, 0, 2), Vec3::Zero());
    EXPECT_LT((g * Vec3(0.5, 0, 0) - Vec3(-2.0, 0, 0)).norm(), 1e-12);
}

}  // namespace
}  // namespace mocap::fusion
