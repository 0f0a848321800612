#include "skeleton/forward_kinematics.hpp"

#include <gtest/gtest.h>

namespace mocap::skeleton {
namespace {

std::size_t idx(const BodyModel& m, std::string_view n) {
    return static_cast<std::size_t>(m.index_of(n));
}

TEST(ForwardKinematics, TPoseGeometry) {
    const BodyModel m = default_body_model(1.75);
    const auto q = identity_quats();
    KinematicPose pose;
    forward_kinematics(m, q, root_position(m), pose);
    EXPECT_EQ(pose.segment_count, 15u);
    // Arm span: hand tip to hand tip = the sum of the lateral offsets on both sides.
    double span = 0;
    for (const auto& n : {seg::kLeftUpperArm, seg::kLeftForearm, seg::kLeftHand, seg::kRightUpperArm,
                          seg::kRightForearm, seg::kRightHand}) {
        span += std::abs(m.segments[idx(m, n)].offset_m.y());
    }
    span += std::abs(m.segments[idx(m, seg::kLeftHand)].end_m.y()) +
            std::abs(m.segments[idx(m, seg::kRightHand)].end_m.y());
    const double measured =
        pose.end_position_m[idx(m, seg::kLeftHand)].y() - pose.end_position_m[idx(m, seg::kRightHand)].y();
    EXPECT_NEAR(measured, span, 1e-12);
    EXPECT_NEAR(measured, (0.259 + 2 * (0.186 + 0.146 + 0.108)) * 1.75, 1e-12);  // Winter ratios
    // Feet on the floor, head top at full height, hands at shoulder height.
    EXPECT_NEAR(pose.end_position_m[idx(m, seg::kLeftFoot)].z(), 0.0, 1e-12);
    EXPECT_NEAR(pose.end_position_m[idx(m, seg::kHead)].z(), 1.75, 1e-12);
    EXPECT_NEAR(pose.end_position_m[idx(m, seg::kRightHand)].z(), 0.818 * 1.75, 1e-12);
    EXPECT_GT(pose.end_position_m[idx(m, seg::kLeftFoot)].x(), pose.joint_position_m[idx(m, seg::kLeftFoot)].x());
}

TEST(ForwardKinematics, RotationsMoveTheChain) {
    const BodyModel m = default_body_model(1.75);
    auto q = identity_quats();
    // Left knee flexed 90°: the calf points backwards (-x), the foot follows it.
    const Quat flex = Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()));
    q[idx(m, seg::kLeftCalf)] = flex;
    q[idx(m, seg::kLeftFoot)] = flex;
    KinematicPose pose;
    const Vec3 root(1.0, 2.0, 0.9);
    forward_kinematics(m, q, root, pose);
    const Vec3 knee = pose.joint_position_m[idx(m, seg::kLeftCalf)];
    const Vec3 ankle = pose.joint_position_m[idx(m, seg::kLeftFoot)];
    EXPECT_NEAR(knee.z(), root.z() - 0.245 * 1.75, 1e-12);
    EXPECT_NEAR(ankle.z(), knee.z(), 1e-12);
    EXPECT_NEAR(ankle.x(), knee.x() - 0.246 * 1.75, 1e-12);
    EXPECT_LT((pose.joint_position_m[0] - root).norm(), 1e-15);

    // Turning the whole body 90° about up turns every position about the root.
    auto turned = identity_quats();
    const Quat yaw = Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
    for (std::size_t i = 0; i < m.size(); ++i)
        turned[i] = yaw;
    KinematicPose a, b;
    forward_kinematics(m, identity_quats(), root, a);
    forward_kinematics(m, turned, root, b);
    for (std::size_t i = 0; i < m.size(); ++i) {
        EXPECT_LT((b.end_position_m[i] - (root + yaw._transformVector(a.end_position_m[i] - root))).norm(), 1e-12);
    }
}

}  // namespace
}  // namespace mocap::skeleton
