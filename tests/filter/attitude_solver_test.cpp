#include "filter/attitude_solver.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace mocap::filter {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

math::Quat random_quat(std::mt19937& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    return math::Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

double qdist(const math::Quat& a, const math::Quat& b) {
    return math::angle_rad(a * b.conjugate());
}

// Noiseless measurements of a sensor at attitude q (specific force at rest = up).
struct Pair {
    math::Vec3 accel, mag;
};
Pair measure(const math::Quat& q_earth_sensor, double dip_rad, double g = 9.81, double b_ut = 48.0) {
    const math::Quat qi = q_earth_sensor.conjugate();
    return {math::rotate(qi, math::Vec3(0, 0, g)), math::rotate(qi, b_ut * field_direction_enu(dip_rad))};
}

TEST(AttitudeSolver, LevelSensorFacingNorthIsIdentity) {
    // Convention check: a level sensor at rest reads +g on z and the field north and down.
    const math::Vec3 h = field_direction_enu(60 * kDeg);
    EXPECT_NEAR(h.y(), 0.5, 1e-12);
    EXPECT_NEAR(h.z(), -std::sqrt(3.0) / 2, 1e-12);
    const AttitudeSolution s =
        solve_lma(math::Vec3(0, 0, 9.81), 50.0 * h, h, math::quat_from_rotvec(math::Vec3(0.3, -0.2, 1.0)));
    ASSERT_TRUE(s.ok());
    EXPECT_LT(qdist(s.q_earth_sensor, math::Quat::Identity()), 1e-9);
    EXPECT_NEAR(measured_dip_rad(math::Vec3(0, 0, 9.81), 50.0 * h), 60 * kDeg, 1e-12);
}

TEST(AttitudeSolver, RecoversRandomAttitudesFromNoiselessVectors) {
    std::mt19937 rng(11);
    for (int i = 0; i < 500; ++i) {
        const math::Quat truth = random_quat(rng);
        const double dip = (i % 7) * 12.0 * kDeg - 30 * kDeg;  // -30° .. 42°
        const Pair m = measure(truth, dip);
        const math::Vec3 h_ref = field_direction_enu(dip);
        // Warm start a few degrees off, as inside a filter.
        const math::Quat start = truth * math::quat_from_rotvec(math::Vec3(0.05, -0.08, 0.1));
        const AttitudeSolution s = solve_lma(m.accel, m.mag, h_ref, start);
        ASSERT_TRUE(s.ok());
        EXPECT_LT(qdist(s.q_earth_sensor, truth), 1e-6) << i;
        EXPECT_LE(s.iterations, 6);
        const AttitudeSolution t = solve_triad(m.accel, m.mag, h_ref);
        ASSERT_TRUE(t.ok());
        EXPECT_LT(qdist(t.q_earth_sensor, truth), 1e-6) << i;
        EXPECT_LT(t.residual, 1e-9);
    }
}

TEST(AttitudeSolver, ConvergesFromFarOffStarts) {
    std::mt19937 rng(12);
    LmaParams p;
    p.max_iterations = 50;
    int worst_iter = 0;
    for (int i = 0; i < 500; ++i) {
        const math::Quat truth = random_quat(rng);
        const Pair m = measure(truth, 60 * kDeg);
        // Start 90°..170° away about a random axis.
        const double ang = (90.0 + 80.0 * (i % 9) / 8.0) * kDeg;
        const math::Vec3 axis = random_quat(rng).vec().normalized();
        const math::Quat start = math::quat_from_rotvec(ang * axis) * truth;
        const AttitudeSolution s = solve_lma(m.accel, m.mag, field_direction_enu(60 * kDeg), start, p);
        ASSERT_TRUE(s.ok());
        EXPECT_LT(qdist(s.q_earth_sensor, truth), 1e-6) << i << " start " << ang / kDeg << "°";
        worst_iter = std::max(worst_iter, s.iterations);
    }
    EXPECT_LT(worst_iter, 50);
    // The paper's initial estimate as a start, identity truth.
    const math::Quat paper_start = math::Quat(0.2, 0.5, 0.7, 0.3).normalized();
    const Pair m = measure(math::Quat::Identity(), 60 * kDeg);
    const AttitudeSolution s = solve_lma(m.accel, m.mag, field_direction_enu(60 * kDeg), paper_start, p);
    EXPECT_LT(qdist(s.q_earth_sensor, math::Quat::Identity()), 1e-6);
}

TEST(AttitudeSolver, InclinationOnlyChangesTheReferenceNotTheAnswer) {
    std::mt19937 rng(13);
    for (double dip_deg : {-75.0, -40.0, 0.0, 20.0, 60.0, 80.0, 85.0}) {
        for (int i = 0; i < 50; ++i) {
            const math::Quat truth = random_quat(rng);
            const Pair m = measure(truth, dip_deg * kDeg);
            const math::Vec3 h_ref = field_direction_enu(dip_deg * kDeg);
            const AttitudeSolution t = solve_triad(m.accel, m.mag, h_ref);
            const AttitudeSolution s = solve_lma(m.accel, m.mag, h_ref, t.q_earth_sensor);
            ASSERT_TRUE(s.ok());
            EXPECT_LT(qdist(s.q_earth_sensor, truth), 1e-6) << dip_deg;
            EXPECT_NEAR(measured_dip_rad(m.accel, m.mag), dip_deg * kDeg, 1e-9);
        }
    }
}

TEST(AttitudeSolver, OwnDipReferenceMatchesTheMeasuredDipWithoutTrig) {
    std::mt19937 rng(14);
    for (int i = 0; i < 100; ++i) {
        const math::Quat truth = random_quat(rng);
        const double dip = (i % 9) * 20.0 * kDeg - 80 * kDeg;
        const Pair m = measure(truth, dip);
        math::Vec3 h;
        ASSERT_TRUE(own_dip_field_direction(m.accel, m.mag, h));
        EXPECT_LT((h - field_direction_enu(dip)).norm(), 1e-9);
        // With its own dip even a disturbed pair is consistent: LMA lands on TRIAD's answer.
        math::Vec3 h2;
        ASSERT_TRUE(own_dip_field_direction(m.accel, m.mag + math::Vec3(3, -2, 1), h2));
        const AttitudeSolution s2 = solve_lma(m.accel, m.mag + math::Vec3(3, -2, 1), h2, truth);
        const AttitudeSolution t = solve_triad(m.accel, m.mag + math::Vec3(3, -2, 1), h2);
        EXPECT_LT(qdist(s2.q_earth_sensor, t.q_earth_sensor), 1e-6);
        EXPECT_LT(s2.residual, 1e-6);
    }
    math::Vec3 h;
    EXPECT_FALSE(own_dip_field_direction(math::Vec3::Zero(), math::Vec3(0, 1, 0), h));
    EXPECT_FALSE(own_dip_field_direction(math::Vec3(0, 0, 1), math::Vec3(0, 0, -2), h));
}

TEST(AttitudeSolver, NoisyFieldTiltsLmaButNotTriad) {
    // LMA weighs both directions alike (the paper); TRIAD takes tilt from the accelerometer.
    const math::Quat truth = math::quat_from_rotvec(math::Vec3(0.2, -0.1, 0.7));
    Pair m = measure(truth, 60 * kDeg);
    m.mag += math::rotate(truth.conjugate(), math::Vec3(8.0, 0.0, 8.0));  // µT, in earth axes
    const math::Vec3 h_ref = field_direction_enu(60 * kDeg);
    const AttitudeSolution t = solve_triad(m.accel, m.mag, h_ref);
    const AttitudeSolution s = solve_lma(m.accel, m.mag, h_ref, truth);
    const math::Quat et = t.q_earth_sensor * truth.conjugate();
    const math::Quat es = s.q_earth_sensor * truth.conjugate();
    EXPECT_LT(math::error_inclination_rad(et), 1e-9);
    EXPECT_GT(math::error_inclination_rad(es), 0.5 * kDeg);
    EXPECT_GT(math::error_heading_rad(et), 1 * kDeg);
}

TEST(AttitudeSolver, DegenerateInputsReturnAStatusNotNaN) {
    const math::Vec3 h = field_direction_enu(60 * kDeg);
    const math::Vec3 g(0, 0, 9.81);
    const auto check = [&](const math::Vec3& a, const math::Vec3& m, AttitudeStatus want) {
        const AttitudeSolution s = solve_lma(a, m, h, math::Quat::Identity());
        EXPECT_EQ(s.status, want) << to_string(s.status);
        EXPECT_TRUE(s.q_earth_sensor.coeffs().allFinite());
        const AttitudeSolution t = solve_triad(a, m, h);
        EXPECT_EQ(t.status, want) << to_string(t.status);
        EXPECT_TRUE(t.q_earth_sensor.coeffs().allFinite());
    };
    check(math::Vec3::Zero(), 50 * h, AttitudeStatus::zero_accel);
    check(g, math::Vec3::Zero(), AttitudeStatus::zero_mag);
    check(g, math::Vec3(0, 0, -40.0), AttitudeStatus::parallel_vectors);
    check(g, math::Vec3(0.1, 0, 40.0), AttitudeStatus::parallel_vectors);
    check(math::Vec3(0, std::nan(""), 9.81), 50 * h, AttitudeStatus::not_finite);
    check(g, math::Vec3(std::numeric_limits<double>::infinity(), 0, 0), AttitudeStatus::not_finite);
    // A vertical reference field cannot give heading either.
    const AttitudeSolution v = solve_triad(g, math::Vec3(1, 10, -40), field_direction_enu(90 * kDeg));
    EXPECT_EQ(v.status, AttitudeStatus::parallel_vectors);
    EXPECT_TRUE(std::isnan(measured_dip_rad(math::Vec3::Zero(), h)));
}

}  // namespace
}  // namespace mocap::filter
