// mocap-sim stream's simulated sensor node: readings derived from the truth, and the CAN
// frames decoded by the wire library back to that truth within quantisation.
#include <gtest/gtest.h>

#include <cmath>

#include "math/quaternion.hpp"
#include "mocap_wire/mw_can.h"
#include "mocap_wire/mw_scale.h"
#include "sim/stream_command.hpp"
#include "sim/stream_motion.hpp"
#include "sim/stream_node.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = M_PI / 180.0;

TEST(StreamNode, GyroIntegratesBackToTheTruthOverAWalk) {
    const auto model = skeleton::default_body_model();
    const StreamMotion walk = StreamMotion::walk(model, 1.0);
    const double dt = 0.01;
    const Quat mount = math::quat_from_rotvec(Vec3(0.2, -0.3, 0.1));
    std::array<Quat, kMaxSegments> q_prev, q_cur;
    Vec3 root;
    for (std::size_t seg : {0u, 4u, 10u}) {
        walk.orientations(0.0, 0.3, Vec3::Zero(), q_prev, root);
        Quat q_est = q_prev[seg] * mount;
        for (int k = 1; k <= 1000; ++k) {
            walk.orientations(k * dt, 0.3, Vec3::Zero(), q_cur, root);
            walk.orientations((k - 1) * dt, 0.3, Vec3::Zero(), q_prev, root);
            const SensorReading r = ideal_reading(q_prev[seg] * mount, q_cur[seg] * mount, dt, Vec3::Zero());
            q_est = (q_est * math::quat_exp(0.5 * dt * r.gyro_rad_s)).normalized();
        }
        EXPECT_LT(math::angle_rad(math::conj(q_est) * (q_cur[seg] * mount)), 1e-9) << "segment " << seg;
    }
}

TEST(StreamNode, AtRestSpecificForceIsGravityAndFieldIsRotated) {
    const Quat q = math::quat_from_rotvec(Vec3(0.4, -1.1, 2.0));
    const SensorReading r = ideal_reading(q, q, 0.01, Vec3::Zero());
    const Vec3 g_sensor = math::rotate(math::conj(q), Vec3(0, 0, MW_STANDARD_GRAVITY_M_S2));
    EXPECT_LT((r.accel_m_s2 - g_sensor).norm(), 1e-6);
    EXPECT_LT(r.gyro_rad_s.norm(), 1e-12);
    EXPECT_LT((math::rotate(q, r.mag_ut) - stream_mag_earth_ut()).norm(), 1e-9);
    const Vec3 m = stream_mag_earth_ut();
    EXPECT_NEAR(m.norm(), 50.0, 1e-9);
    EXPECT_NEAR(std::atan2(-m.z(), m.y()), 60.0 * kDeg, 1e-9) << "dip 60°, pointing north and down";
    // With linear acceleration: f = R(q)ᵀ (a_lin + g).
    const Vec3 lin(0.8, -2.0, 1.5);
    const SensorReading moving = ideal_reading(q, q, 0.01, lin);
    EXPECT_LT((math::rotate(q, moving.accel_m_s2) - (lin + Vec3(0, 0, MW_STANDARD_GRAVITY_M_S2))).norm(), 1e-6);
    // Level and at rest: +1 g on +z, as a real MPU9250.
    const SensorReading level = ideal_reading(Quat::Identity(), Quat::Identity(), 0.01, Vec3::Zero());
    EXPECT_NEAR(level.accel_m_s2.z(), MW_STANDARD_GRAVITY_M_S2, 1e-6);
}

TEST(StreamNode, WalkSensorAccelerationIsZeroAtRestAndCentripetalWhileWalking) {
    // The stream's finite difference of sensor positions: zero in the still T-pose; while
    // walking, the gait's oscillations average out over whole strides and what is left is
    // the circle's centripetal v²/R = 1.2² / 4 = 0.36 m/s².
    const auto model = skeleton::default_body_model();
    const StreamMotion walk = StreamMotion::walk(model, 2.0);
    const double dt = 0.01;
    auto accel = [&](double t) {
        BodyPose a, b, c;
        walk.pose(t - dt, 0.0, Vec3::Zero(), a);
        walk.pose(t, 0.0, Vec3::Zero(), b);
        walk.pose(t + dt, 0.0, Vec3::Zero(), c);
        return Vec3((c.sensor_position_m[0] - 2.0 * b.sensor_position_m[0] + a.sensor_position_m[0]) / (dt * dt));
    };
    EXPECT_LT(accel(1.0).norm(), 1e-9);
    Vec3 mean = Vec3::Zero();
    const int n = 1000;  // 10 s = 9 strides at 0.9 Hz
    for (int k = 0; k < n; ++k)
        mean += accel(6.0 + k * dt) / n;
    // The heading turns by θ = v·T/R = 3 rad over the window, so the mean of the centripetal
    // vector shrinks by sin(θ/2)/(θ/2).
    EXPECT_NEAR(std::hypot(mean.x(), mean.y()), 0.36 * std::sin(1.5) / 1.5, 0.02);
    EXPECT_LT(std::abs(mean.z()), 0.05);
}

TEST(StreamNode, RawFramesDecodeToTheTruthWithinQuantisation) {
    SimulatedNode node(7, false, 42, 7, stream_node_noise(0.0));
    const Quat q0 = math::quat_from_rotvec(Vec3(0.3, 0.2, -0.5));
    const Quat q1 = q0 * math::quat_from_rotvec(Vec3(0.02, -0.01, 0.015));
    const Vec3 lin(1.5, -0.5, 2.0);
    mw_can_frame frames[3];
    ASSERT_EQ(node.raw_frames(q0, q1, 0.01, lin, 0x12345u, frames), 3);
    const SensorReading truth = ideal_reading(q0 * node.q_segment_sensor(), q1 * node.q_segment_sensor(), 0.01, lin);
    mw_message msg{};
    float v[3];
    ASSERT_EQ(mw_can_decode(&frames[0], &msg), MW_OK);
    EXPECT_EQ(msg.function, MW_FN_ACCEL);
    EXPECT_EQ(msg.u.raw.node_id, 7);
    EXPECT_EQ(msg.u.raw.counter_low, 0x2345u);
    ASSERT_EQ(mw_accel_to_m_s2(msg.u.raw.xyz, MW_ACCEL_16G, v), MW_OK);
    for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(v[i], truth.accel_m_s2[i], 0.51 * mw_accel_m_s2_per_lsb(MW_ACCEL_16G));
    ASSERT_EQ(mw_can_decode(&frames[1], &msg), MW_OK);
    EXPECT_EQ(msg.function, MW_FN_GYRO);
    ASSERT_EQ(mw_gyro_to_rad_s(msg.u.raw.xyz, MW_GYRO_2000DPS, v), MW_OK);
    for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(v[i], truth.gyro_rad_s[i], 0.51 * mw_gyro_rad_s_per_lsb(MW_GYRO_2000DPS));
    ASSERT_EQ(mw_can_decode(&frames[2], &msg), MW_OK);
    EXPECT_EQ(msg.function, MW_FN_MAG);
    ASSERT_EQ(mw_mag_to_ut(msg.u.raw.xyz, v), MW_OK);
    for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(v[i], truth.mag_ut[i], 0.51 * MW_MAG_UT_PER_LSB);
    EXPECT_GT(truth.gyro_rad_s.norm(), 1.0) << "the test moved the sensor";
}

TEST(StreamNode, MagnetometerReadsTheFieldAtItsPositionPlusItsMagnet) {
    // --magnetic-env: the caller's field at the sensor; --magnet: a constant offset in the
    // sensor frame, whatever the orientation.
    SimulatedNode node(5, false, 42, 5, stream_node_noise(0.0));
    const Vec3 hard_iron(12.0, -20.0, 5.0);
    node.set_hard_iron_ut(hard_iron);
    const Vec3 field(8.0, 19.0, -41.0);  // a disturbed field, ENU
    for (const Vec3& rv : {Vec3(0.3, 0.2, -0.5), Vec3(-1.2, 0.7, 2.1)}) {
        const Quat q = math::quat_from_rotvec(rv);
        mw_can_frame frames[3];
        ASSERT_EQ(node.raw_frames(q, q, 0.01, Vec3::Zero(), 9u, frames, field), 3);
        mw_message msg{};
        float v[3];
        ASSERT_EQ(mw_can_decode(&frames[2], &msg), MW_OK);
        ASSERT_EQ(mw_mag_to_ut(msg.u.raw.xyz, v), MW_OK);
        const Vec3 expected = math::rotate(math::conj(q * node.q_segment_sensor()), field) + hard_iron;
        for (int i = 0; i < 3; ++i)
            EXPECT_NEAR(v[i], expected[i], 0.51 * MW_MAG_UT_PER_LSB);
    }
    const SensorReading r = ideal_reading(Quat::Identity(), Quat::Identity(), 0.01, Vec3::Zero(), field);
    EXPECT_LT((r.mag_ut - field).norm(), 1e-12);
}

TEST(StreamNode, AttitudeFrameDecodesToTheSensorOrientation) {
    SimulatedNode node(3, false, 42, 3, stream_node_noise(0.0));
    const Quat q = math::quat_from_rotvec(Vec3(-0.7, 0.4, 1.9));
    mw_can_frame frame{};
    ASSERT_EQ(node.attitude_frame(q, 20000u, &frame), 1);
    mw_attitude att{};
    ASSERT_EQ(mw_attitude_decode(&frame, &att), MW_OK);
    EXPECT_EQ(att.counter_low, 20000u & 0x3FFFu);
    const Quat decoded(att.q[0], att.q[1], att.q[2], att.q[3]);
    EXPECT_LT(math::angle_rad(math::conj(decoded) * (q * node.q_segment_sensor())), 2e-4);
}

TEST(StreamNode, MountingAndBiasAreSeededAndBounded) {
    for (std::uint64_t stream = 1; stream <= 40; ++stream) {
        SimulatedNode node(static_cast<std::uint8_t>(stream), false, 9, stream, stream_node_noise(1.0));
        EXPECT_LE(math::angle_rad(node.q_segment_sensor()), 30.0 * kDeg + 1e-12);
        for (int i = 0; i < 3; ++i) {
            EXPECT_GE(std::abs(node.gyro_bias_rad_s()[i]), 0.5 * kDeg - 1e-12);
            EXPECT_LE(std::abs(node.gyro_bias_rad_s()[i]), 2.0 * kDeg + 1e-12);
        }
        SimulatedNode same(static_cast<std::uint8_t>(stream), false, 9, stream, stream_node_noise(1.0));
        EXPECT_EQ(same.q_segment_sensor().coeffs(), node.q_segment_sensor().coeffs());
        // The root's node keeps its x axis forward (facing = "sensor" calibration).
        SimulatedNode root(1, true, 9, stream, stream_node_noise(1.0));
        EXPECT_LT((math::rotate(root.q_segment_sensor(), Vec3::UnitX()) - Vec3::UnitX()).norm(), 1e-12);
    }
}

TEST(StreamCommand, ParsesDropouts) {
    NodeDropout d;
    std::string error;
    ASSERT_TRUE(parse_dropout("4:1.5:3", &d, &error)) << error;
    EXPECT_EQ(d.node, 4);
    EXPECT_DOUBLE_EQ(d.start_s, 1.5);
    EXPECT_DOUBLE_EQ(d.end_s, 3.0);
    EXPECT_FALSE(parse_dropout("4:3:1", &d, &error));
    EXPECT_FALSE(parse_dropout("0:1:2", &d, &error));
    EXPECT_FALSE(parse_dropout("4:1:2x", &d, &error));
    EXPECT_FALSE(parse_dropout("4:1", &d, &error));
    // What sscanf used to let through: a node number that overflows int, a field with
    // trailing characters, a missing field, a fourth field, space before a number.
    EXPECT_FALSE(parse_dropout("4294967300:1:2", &d, &error));
    EXPECT_FALSE(parse_dropout("4x:1:2", &d, &error));
    EXPECT_FALSE(parse_dropout("4::2", &d, &error));
    EXPECT_FALSE(parse_dropout("4:1:2:3", &d, &error));
    EXPECT_FALSE(parse_dropout(" 4:1:2", &d, &error));
    EXPECT_FALSE(parse_dropout("4:nan:2", &d, &error));
    EXPECT_NE(error.find("NODE:START_S:END_S"), std::string::npos);
}

TEST(StreamCommand, ParsesMagnets) {
    SegmentMagnet m;
    std::string error;
    ASSERT_TRUE(parse_magnet("left_hand", &m, &error)) << error;
    EXPECT_EQ(m.segment, "left_hand");
    EXPECT_DOUBLE_EQ(m.field_ut, 30.0) << "the default";
    ASSERT_TRUE(parse_magnet("trunk:45.5", &m, &error)) << error;
    EXPECT_EQ(m.segment, "trunk");
    EXPECT_DOUBLE_EQ(m.field_ut, 45.5);
    for (const char* bad : {"", ":10", "trunk:", "trunk:0", "trunk:-5", "trunk:x", "trunk:10:2", "trunk:5000"}) {
        EXPECT_FALSE(parse_magnet(bad, &m, &error)) << bad;
        EXPECT_NE(error.find("SEGMENT[:UT]"), std::string::npos);
    }
}

}  // namespace
}  // namespace mocap::sim
