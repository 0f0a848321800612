#include "skeleton/joint_angles.hpp"

#include <gtest/gtest.h>

#include <random>

#include "skeleton/calibration.hpp"

namespace mocap::skeleton {
namespace {

double deg(double r) {
    return r * 180.0 / M_PI;
}
double rad(double d) {
    return d * M_PI / 180.0;
}
Quat about(const Vec3& axis, double deg_) {
    return Quat(Eigen::AngleAxisd(rad(deg_), axis.normalized()));
}

constexpr double kTol = 1e-9;  // degrees; constructed poses are exact

void expect_angles(const JointAngles& a, double flex, double abd, double rot, const char* what) {
    EXPECT_NEAR(deg(a.flexion_rad), flex, kTol) << what;
    EXPECT_NEAR(deg(a.abduction_rad), abd, kTol) << what;
    EXPECT_NEAR(deg(a.rotation_rad), rot, kTol) << what;
}

TEST(JointAngles, PureKneeFlexion) {
    // Calf rotated 30° about the medio-lateral axis, foot moving backwards.
    const Quat thigh = about(Vec3(0.3, -0.2, 1), 70);  // any parent orientation
    for (const Side side : {Side::kLeft, Side::kRight}) {
        const Quat calf = thigh * about(Vec3::UnitY(), 30);
        expect_angles(joint_angles(JointKind::kKnee, side, thigh, calf), 30, 0, 0, "knee");
        // The calf's tip really moved backwards in the thigh frame.
        EXPECT_LT(relative_rotation(thigh, calf)._transformVector(-Vec3::UnitZ()).x(), 0.0);
    }
}

TEST(JointAngles, HipAnkleSignsAreAnatomical) {
    const Quat pelvis = Quat::Identity();
    // Thigh forward 40° (tip of the thigh moves to +x).
    expect_angles(joint_angles(JointKind::kHip, Side::kLeft, pelvis, about(Vec3::UnitY(), -40)), 40, 0, 0, "hip flex");
    // Left thigh out to the left (+y) 20°, right thigh out to the right (-y) 20°.
    expect_angles(joint_angles(JointKind::kHip, Side::kLeft, pelvis, about(Vec3::UnitX(), 20)), 0, 20, 0, "l abd");
    expect_angles(joint_angles(JointKind::kHip, Side::kRight, pelvis, about(Vec3::UnitX(), -20)), 0, 20, 0, "r abd");
    // Toes turning inward 15°: left turns toward -y (clockwise from above), right toward +y.
    expect_angles(joint_angles(JointKind::kHip, Side::kLeft, pelvis, about(Vec3::UnitZ(), -15)), 0, 0, 15, "l int");
    expect_angles(joint_angles(JointKind::kHip, Side::kRight, pelvis, about(Vec3::UnitZ(), 15)), 0, 0, 15, "r int");
    // Ankle: toes up 10° is dorsiflexion.
    const Quat foot = about(Vec3::UnitY(), -10);
    EXPECT_GT(foot._transformVector(Vec3::UnitX()).z(), 0.0);
    expect_angles(joint_angles(JointKind::kAnkle, Side::kLeft, pelvis, foot), 10, 0, 0, "dorsiflexion");
}

TEST(JointAngles, ShoulderAndElbow) {
    const BodyModel m = default_body_model();
    const Quat trunk = about(Vec3::UnitZ(), 33);
    const auto tpose = identity_quats();
    const auto npose = pose_orientations(m, CalibrationPose::kNPose);
    for (const Side side : {Side::kLeft, Side::kRight}) {
        const auto ua =
            static_cast<std::size_t>(m.index_of(side == Side::kLeft ? seg::kLeftUpperArm : seg::kRightUpperArm));
        // T-pose: arms abducted 90°; N-pose: anatomical neutral.
        expect_angles(joint_angles(JointKind::kShoulder, side, trunk, trunk * tpose[ua]), 0, 90, 0, "T-pose");
        expect_angles(joint_angles(JointKind::kShoulder, side, trunk, trunk * npose[ua]), 0, 0, 0, "N-pose");
        // From the N-pose, the arm swung forward 45°: its tip moves to +x.
        const Quat fwd = trunk * about(Vec3::UnitY(), -45) * npose[ua];
        EXPECT_GT((trunk.conjugate() * fwd)._transformVector(m.segments[ua].end_m).x(), 0.0);
        expect_angles(joint_angles(JointKind::kShoulder, side, trunk, fwd), 45, 0, 0, "shoulder flexion");
        // Elbow: from the T-pose the forearm swings forward 90° (palms down).
        const double s = side == Side::kLeft ? -1.0 : 1.0;
        const Quat forearm = trunk * about(Vec3::UnitZ(), s * 90);
        const auto fa =
            static_cast<std::size_t>(m.index_of(side == Side::kLeft ? seg::kLeftForearm : seg::kRightForearm));
        EXPECT_NEAR((trunk.conjugate() * forearm)._transformVector(m.segments[fa].end_m).normalized().x(), 1.0, 1e-12);
        expect_angles(joint_angles(JointKind::kElbow, side, trunk, forearm), 90, 0, 0, "elbow flexion");
    }
}

TEST(JointAngles, RoundTripAndMirrorSymmetry) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1.2, 1.2);
    std::normal_distribution<double> n;
    for (const JointKind k :
         {JointKind::kHip, JointKind::kKnee, JointKind::kAnkle, JointKind::kShoulder, JointKind::kElbow}) {
        for (int i = 0; i < 200; ++i) {
            const JointAngles a{u(rng), u(rng), u(rng)};
            const Quat parent = Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
            for (const Side side : {Side::kLeft, Side::kRight}) {
                const JointAngles b = joint_angles(k, side, parent, child_orientation(k, side, parent, a));
                EXPECT_NEAR(b.flexion_rad, a.flexion_rad, 1e-9);
                EXPECT_NEAR(b.abduction_rad, a.abduction_rad, 1e-9);
                EXPECT_NEAR(b.rotation_rad, a.rotation_rad, 1e-9);
            }
            // Mirror image across the sagittal plane (y -> -y): (w, x, y, z) -> (w, -x, y, -z).
            const Quat c = child_orientation(k, Side::kLeft, parent, a);
            const auto mirror = [](const Quat& q) { return Quat(q.w(), -q.x(), q.y(), -q.z()); };
            const JointAngles r = joint_angles(k, Side::kRight, mirror(parent), mirror(c));
            EXPECT_NEAR(r.flexion_rad, a.flexion_rad, 1e-9);
            EXPECT_NEAR(r.abduction_rad, a.abduction_rad, 1e-9);
            EXPECT_NEAR(r.rotation_rad, a.rotation_rad, 1e-9);
        }
    }
}

TEST(JointAngles, DefaultSpecsCoverTenJoints) {
    const BodyModel m = default_body_model();
    const auto specs = default_joint_specs(m);
    ASSERT_EQ(specs.size(), 10u);
    EXPECT_EQ(specs[2].name, "left_knee");
    EXPECT_EQ(specs[2].parent_segment, m.index_of("left_thigh"));
    EXPECT_EQ(specs[2].child_segment, m.index_of("left_calf"));
    auto q = identity_quats();
    q[static_cast<std::size_t>(m.index_of("left_calf"))] = about(Vec3::UnitY(), 30);
    q[static_cast<std::size_t>(m.index_of("left_foot"))] = about(Vec3::UnitY(), 30);
    std::array<JointAngles, 10> out;
    compute_joint_angles(specs, q, out);
    EXPECT_NEAR(deg(out[2].flexion_rad), 30, kTol);    // knee flexed
    EXPECT_NEAR(deg(out[4].flexion_rad), 0, kTol);     // ankle unchanged relative to the calf
    EXPECT_NEAR(deg(out[6].abduction_rad), 90, kTol);  // T-pose shoulder
}

}  // namespace
}  // namespace mocap::skeleton

namespace mocap::skeleton {
namespace {

TEST(JointAngles, ShortFrameLeavesMissingJointsAtZero) {
    const BodyModel m = default_body_model();
    const auto specs = default_joint_specs(m);
    auto q = identity_quats();
    std::array<JointAngles, 10> out;
    out.fill(JointAngles{1, 1, 1});
    compute_joint_angles(specs, std::span<const Quat>(q.data(), 3), out);  // pelvis, trunk, head only
    for (const JointAngles& a : out)
        EXPECT_EQ(a.flexion_rad + a.abduction_rad + a.rotation_rad, 0.0);
}

}  // namespace
}  // namespace mocap::skeleton
