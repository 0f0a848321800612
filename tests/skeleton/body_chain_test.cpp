// The chain stage on the default body: which joint is what, axes from a calibration's
// mountings, and a mounting that a disturbed field turned at calibration corrected from the
// knee axis the gyroscopes show.
#include "skeleton/body_chain.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace mocap::skeleton {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Quat axis_angle(const Vec3& axis, double a) {
    return Quat(Eigen::AngleAxisd(a, axis.normalized()));
}

TEST(BodyChain, TheDefaultBodysJoints) {
    const BodyModel m = default_body_model();
    const std::vector<BodyJoint> joints = body_joints(m);
    ASSERT_EQ(joints.size(), m.size() - 1);
    const auto type_of = [&](std::string_view child) {
        for (const BodyJoint& j : joints) {
            if (m.segments[static_cast<std::size_t>(j.def.child)].name == child) return j.def.type;
        }
        ADD_FAILURE() << child;
        return fusion::JointType::kBall;
    };
    EXPECT_EQ(type_of(seg::kLeftCalf), fusion::JointType::kHinge);
    EXPECT_EQ(type_of(seg::kRightCalf), fusion::JointType::kHinge);
    for (auto name : {seg::kLeftForearm, seg::kRightHand, seg::kLeftFoot})
        EXPECT_EQ(type_of(name), fusion::JointType::kTwoDof);
    for (auto name : {seg::kTrunk, seg::kHead, seg::kLeftUpperArm, seg::kRightThigh})
        EXPECT_EQ(type_of(name), fusion::JointType::kBall);
    EXPECT_EQ(heading_flags(fusion::HeadingSource::kJoints), kSegmentHeadingJoints);
    EXPECT_EQ(heading_flags(fusion::HeadingSource::kNone), 0);
}

TEST(BodyChain, AxesInTheSensorsFromTheMountings) {
    const BodyModel m = default_body_model();
    BodyChain chain(m, {});
    Calibration cal;
    cal.segment_count = m.size();
    for (std::size_t i = 0; i < m.size(); ++i) {
        cal.calibrated[i] = true;
        cal.q_sensor_segment[i] = axis_angle(Vec3(0.2, 0.5, 0.8), 0.3 * static_cast<double>(i));
    }
    chain.on_calibration(cal, false);
    const int calf = m.index_of(seg::kLeftCalf), thigh = m.index_of(seg::kLeftThigh);
    for (std::size_t j = 0; j < chain.joints().size(); ++j) {
        if (chain.joints()[j].def.child != calf) continue;
        const fusion::JointStatus st = chain.estimator().status(j);
        ASSERT_TRUE(st.axes_known);
        EXPECT_LT((st.axis_parent - math::rotate(cal.q_sensor_segment[static_cast<std::size_t>(thigh)], Vec3::UnitY()))
                      .norm(),
                  1e-12);
        EXPECT_LT(
            (st.axis_child - math::rotate(cal.q_sensor_segment[static_cast<std::size_t>(calf)], Vec3::UnitY())).norm(),
            1e-12);
    }
}

// A calibration made where the field was 25° off at the calf: its mounting is turned by 25°
// about the T-pose vertical. The knee's axis learned from the motion shows it, and
// refine_calibration turns the mounting back (within a degree).
TEST(BodyChain, ALearnedKneeAxisCorrectsATurnedMounting) {
    const BodyModel m = default_body_model();
    FusionOptions opt;
    opt.estimate_axes = true;
    opt.chain.mode = fusion::HeadingMode::kJoints;
    BodyChain chain(m, opt);
    const auto thigh = static_cast<std::size_t>(m.index_of(seg::kLeftThigh));
    const auto calf = static_cast<std::size_t>(m.index_of(seg::kLeftCalf));
    const Quat mount_thigh = axis_angle(Vec3(0.3, -0.2, 0.9), 0.7);  // q_sensor_segment
    const Quat mount_calf = axis_angle(Vec3(-0.6, 0.5, 0.2), 1.1);
    Calibration cal;
    cal.segment_count = m.size();
    cal.calibrated[thigh] = cal.calibrated[calf] = true;
    cal.q_sensor_segment[thigh] = mount_thigh;
    cal.q_sensor_segment[calf] = (mount_calf * axis_angle(Vec3::UnitZ(), -25.0 * kDeg)).normalized();
    chain.on_calibration(cal, false);

    // The thigh swings and turns; the knee flexes about the segments' y.
    const double dt = 0.01;
    Quat prev_t, prev_c;
    SubjectFrame f;
    f.segment_count = static_cast<std::uint16_t>(m.size());
    std::array<Quat, kMaxSegments> q{};
    std::array<std::uint8_t, kMaxSegments> flags{};
    for (int k = 0; k <= 6000; ++k) {
        const double t = k * dt;
        const Quat seg_t = axis_angle(Vec3::UnitZ(), 0.8 * std::sin(0.4 * t)) *
                           axis_angle(Vec3::UnitY(), 0.6 * std::sin(1.3 * t)) *
                           axis_angle(Vec3::UnitX(), 0.3 * std::sin(0.9 * t));
        const Quat seg_c = seg_t * axis_angle(Vec3::UnitY(), -0.6 - 0.6 * std::sin(1.7 * t));
        const Quat qt = seg_t * mount_thigh.conjugate(), qc = seg_c * mount_calf.conjugate();  // q_earth_sensor
        for (std::size_t i = 0; i < m.size(); ++i) {
            f.segments[i] = SegmentPose{};
            f.segments[i].flags = kSegmentNeverSeen;
            q[i] = Quat::Identity();
        }
        f.sample_us = static_cast<std::int64_t>(std::llround(t * 1e6));
        for (const auto& [i, now, before] : {std::tuple{thigh, qt, prev_t}, std::tuple{calf, qc, prev_c}}) {
            f.segments[i].flags = 0;
            const Vec3 w = k > 0 ? Vec3(math::rotvec_from_quat(before.conjugate() * now) / dt) : Vec3::Zero();
            f.segments[i].rate_rad_s = {static_cast<float>(w.x()), static_cast<float>(w.y()),
                                        static_cast<float>(w.z())};
            q[i] = now;
        }
        chain.apply(f, std::span<Quat>(q.data(), m.size()), std::span<std::uint8_t>(flags.data(), m.size()));
        prev_t = qt;
        prev_c = qc;
    }
    EXPECT_EQ(flags[calf], kSegmentHeadingJoints);
    ASSERT_TRUE(chain.refine_calibration(m, cal));
    EXPECT_LT(math::angle_rad(cal.q_sensor_segment[calf] * mount_calf.conjugate()) / kDeg, 1.0);
    EXPECT_LT(math::angle_rad(cal.q_sensor_segment[thigh] * mount_thigh.conjugate()) / kDeg, 1.0);
    chain.on_calibration(cal, false);
    EXPECT_FALSE(chain.refine_calibration(m, cal));  // nothing left to turn
}

}  // namespace
}  // namespace mocap::skeleton
