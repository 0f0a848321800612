// mocap-sim csv --scenario pendulum: a real two-bar pendulum (its free swing keeps its
// mechanical energy), sensors that read its kinematics, and a lower joint that is close to a
// hinge without being one. Checked without any filter, on ideal sensors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim/pendulum_scenario.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;
const Vec3 kGravityUp(0.0, 0.0, 9.81);

Vec3 vec(const Vec3d& a) {
    return {a[0], a[1], a[2]};
}

const MagneticEnv& clean() {
    static const MagneticEnv env = *MagneticEnv::load("clean", 1, nullptr);
    return env;
}

// The default run (210 s at 100 Hz) on ideal sensors, shared by the tests of this file.
const ChainRecording& ideal_pendulum() {
    static const ChainRecording rec = [] {
        PendulumOptions o;
        o.noise_scale = 0.0;
        return make_pendulum_scenario(o, clean());
    }();
    return rec;
}

/// seg x (along the bar, proximal to distal) in the earth frame.
Vec3 bar_axis(const ChainSensor& s, std::size_t k) {
    return math::rotate(s.rows[k].q_earth_sensor * math::conj(s.q_segment_sensor), Vec3::UnitX());
}

TEST(PendulumScenario, SensorsReadTheKinematicsOnIdealSensors) {
    // At 400 Hz: Numerov's O(dt⁴) residual of this fast motion (the lower bar turns at up to
    // ~20 rad/s) is then ~1e-4 m/s²; at 100 Hz it is up to 0.05 m/s², 256 times more, as it
    // should be.
    PendulumOptions o;
    o.noise_scale = 0.0;
    o.rate_hz = 400.0;
    o.duration_s = 30.0;
    const ChainRecording rec = make_pendulum_scenario(o, clean());
    ASSERT_EQ(rec.sensors.size(), 2u);
    const double dt = 1.0 / rec.rate_hz;
    for (const ChainSensor& s : rec.sensors) {
        ASSERT_EQ(s.rows.size(), 12001u);
        // Gyro: integrating it reproduces the truth.
        Quat q = s.rows[0].q_earth_sensor;
        double worst_q = 0.0;
        for (std::size_t k = 1; k < s.rows.size(); ++k) {
            q = (q * math::quat_exp(0.5 * dt * vec(s.rows[k].sample.gyro_rad_s))).normalized();
            worst_q = std::max(worst_q, math::angle_rad(math::conj(q) * s.rows[k].q_earth_sensor));
        }
        EXPECT_LT(worst_q, 1e-8) << s.name;
        // Accelerometer: Numerov's relation between the positions and a = R f − g
        // (chain_scenario_test.cpp explains it); magnetometer: the clean earth field.
        double worst_a = 0.0, largest = 0.0;
        for (std::size_t k = 1; k + 1 < s.rows.size(); ++k) {
            auto a = [&](std::size_t i) {
                return Vec3(math::rotate(s.rows[i].q_earth_sensor, vec(s.rows[i].sample.accel_m_s2)) - kGravityUp);
            };
            const Vec3 lhs =
                (s.rows[k + 1].position_m - 2.0 * s.rows[k].position_m + s.rows[k - 1].position_m) / (dt * dt);
            worst_a = std::max(worst_a, (lhs - (a(k + 1) + 10.0 * a(k) + a(k - 1)) / 12.0).norm());
            largest = std::max(largest, a(k).norm());
            EXPECT_LT((math::rotate(s.rows[k].q_earth_sensor, vec(s.rows[k].sample.mag_ut)) - clean().earth_field_ut())
                          .norm(),
                      1e-9);
        }
        EXPECT_LT(worst_a, 1e-3) << s.name << " m/s²";
        EXPECT_GT(largest, 5.0) << s.name << ": centripetal and tangential accelerations of a real swing";
    }
}

TEST(PendulumScenario, FreeSwingKeepsItsEnergy) {
    // Released from (70°, −40°) without damping or pushes: kinetic + potential energy of the two
    // bars, computed here from the recorded truth alone (velocities by central differences at
    // 1 kHz), stays what it was. A wrong term in the equations of motion would not.
    PendulumOptions o;
    o.free_swing = true;
    o.rate_hz = 1000.0;
    o.duration_s = 8.0;
    o.noise_scale = 0.0;
    const ChainRecording rec = make_pendulum_scenario(o, clean());
    const auto bodies = pendulum_bodies();
    const double dt = 1.0 / o.rate_hz;
    auto energy = [&](std::size_t k) {
        double e = 0.0;
        for (std::size_t i = 0; i < 2; ++i) {
            const ChainSensor& s = rec.sensors[i];
            const PendulumBody& b = bodies[i];
            const Vec3 v = (s.rows[k + 1].position_m - s.rows[k - 1].position_m) / (2.0 * dt);
            const Vec3 w =
                math::rotvec_from_quat(s.rows[k + 1].q_earth_sensor * math::conj(s.rows[k - 1].q_earth_sensor)) /
                (2.0 * dt);
            const math::Mat3 r = math::to_rotation_matrix(s.rows[k].q_earth_sensor * math::conj(s.q_segment_sensor));
            const Vec3 i_diag(b.width_m * b.width_m + b.thickness_m * b.thickness_m,
                              b.length_m * b.length_m + b.thickness_m * b.thickness_m,
                              b.length_m * b.length_m + b.width_m * b.width_m);
            const math::Mat3 inertia = r * (b.mass_kg / 12.0 * i_diag).asDiagonal() * r.transpose();
            e += 0.5 * b.mass_kg * v.squaredNorm() + 0.5 * w.dot(inertia * w) +
                 b.mass_kg * 9.81 * s.rows[k].position_m.z();
        }
        return e;
    };
    double e_min = 1e9, e_max = -1e9, bend_max = 0.0;
    for (std::size_t k = 1; k + 1 < rec.sensors[0].rows.size(); ++k) {
        const double e = energy(k);
        e_min = std::min(e_min, e);
        e_max = std::max(e_max, e);
        bend_max = std::max(
            bend_max, std::acos(std::clamp(bar_axis(rec.sensors[0], k).dot(bar_axis(rec.sensors[1], k)), -1.0, 1.0)));
    }
    // The swing's energy above the hanging rest: m g Δh of both bars, ~2 J here.
    const Vec3 pivot = pendulum_pivot_m();
    double rest = 0.0;
    for (std::size_t i = 0; i < 2; ++i)
        rest += bodies[i].mass_kg * 9.81 *
                (pivot.z() - (i == 0 ? 0.5 * bodies[0].length_m : bodies[0].length_m + 0.5 * bodies[1].length_m));
    const double swing = e_max - rest;
    EXPECT_GT(swing, 1.0);
    EXPECT_LT((e_max - e_min) / swing, 1e-3) << "energy from " << e_min << " to " << e_max << " J";
    EXPECT_GT(bend_max, 40.0 * kDeg) << "the lower bar swings on its own";
}

TEST(PendulumScenario, LowerJointIsCloseToAHingeButNotOne) {
    const ChainRecording& rec = ideal_pendulum();
    ASSERT_EQ(rec.joints.size(), 1u);
    const ChainJoint& j = rec.joints[0];
    EXPECT_EQ(j.type, "hinge");
    EXPECT_GT(j.axis_wander_deg, 7.0);
    EXPECT_LT(j.axis_wander_deg, 14.0);
    const ChainSensor& p = rec.sensors[0];
    const ChainSensor& c = rec.sensors[1];
    double worst = 0.0, sum = 0.0, centre = 0.0;
    for (std::size_t k = 0; k < p.rows.size(); ++k) {
        const Quat& qp = p.rows[k].q_earth_sensor;
        const Quat& qc = c.rows[k].q_earth_sensor;
        // An exact hinge would keep axis_child on axis_parent (chain_scenario_test.cpp).
        const Vec3 mapped = math::rotate(math::conj(qp) * qc, j.axis_child);
        const double off = std::acos(std::clamp(mapped.dot(j.axis_parent), -1.0, 1.0));
        worst = std::max(worst, off);
        sum += off;
        centre = std::max(centre, (p.rows[k].position_m + math::rotate(qp, j.r_parent_m) - c.rows[k].position_m -
                                   math::rotate(qc, j.r_child_m))
                                      .norm());
    }
    EXPECT_GT(worst, 4.0 * kDeg) << "not an exact hinge";
    EXPECT_LT(worst, 25.0 * kDeg) << "but close to one";
    EXPECT_LT(sum / static_cast<double>(p.rows.size()), 6.0 * kDeg);
    EXPECT_LT(centre, 1e-9) << "the joint centre is one point seen from both sensors";
}

TEST(PendulumScenario, HangsStillThenKeepsSwingingWithLargeAmplitudes) {
    const ChainRecording& rec = ideal_pendulum();
    const ChainSensor& upper = rec.sensors[0];
    const double dt = 1.0 / rec.rate_hz;
    for (std::size_t k = 0; k * dt < 2.99; ++k)
        ASSERT_FALSE(upper.rows[k].moving) << "still for 3 s, t = " << k * dt;
    // The upper bar's largest angle from hanging straight down in each 15 s after the start.
    double smallest_window = 1e9, largest = 0.0;
    for (double t0 = 5.0; t0 + 15.0 <= rec.duration_s; t0 += 15.0) {
        double window = 0.0;
        for (auto k = static_cast<std::size_t>(t0 / dt); k < static_cast<std::size_t>((t0 + 15.0) / dt); ++k)
            window = std::max(window, std::acos(std::clamp(-bar_axis(upper, k).z(), -1.0, 1.0)));
        smallest_window = std::min(smallest_window, window);
        largest = std::max(largest, window);
    }
    EXPECT_GT(smallest_window, 25.0 * kDeg) << "pushed again before it settles";
    EXPECT_GT(largest, 45.0 * kDeg);
    EXPECT_LT(largest, 120.0 * kDeg) << "a pendulum, not a propeller";
}

}  // namespace
}  // namespace mocap::sim
