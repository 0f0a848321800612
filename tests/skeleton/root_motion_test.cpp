#include "skeleton/root_motion.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "skeleton/bvh.hpp"

namespace mocap::skeleton {
namespace {

TEST(RootMotion, StandingStillStaysPutOnTheFloor) {
    const BodyModel m = default_body_model();
    FootContactRootTracker t(m);
    SkeletonPose pose;
    const auto q = identity_quats();
    for (int f = 0; f < 100; ++f) t.update(m, q, pose);
    EXPECT_LT((pose.joint_position_m[0] - root_position(m)).norm(), 1e-12);
    EXPECT_NEAR(pose.end_position_m[static_cast<std::size_t>(m.index_of(seg::kLeftFoot))].z(), 0.0, 1e-12);
}

TEST(RootMotion, KneeBendLowersThePelvis) {
    const BodyModel m = default_body_model();
    FootContactRootTracker t(m);
    SkeletonPose pose;
    auto q = identity_quats();
    // Squat-like: thighs forward 40°, calves upright, feet flat: the pelvis drops.
    const Quat thigh(Eigen::AngleAxisd(-40 * M_PI / 180, Vec3::UnitY()));
    for (const auto n : {seg::kLeftThigh, seg::kRightThigh}) q[static_cast<std::size_t>(m.index_of(n))] = thigh;
    const Vec3 root = t.update(m, q, pose);
    const double thigh_len = 0.245 * 1.75;
    EXPECT_NEAR(root.z(), m.root_height_m - thigh_len * (1 - std::cos(40 * M_PI / 180)), 1e-9);
}

// Real walk: segment orientations from the CMU clip drive the default 15-segment model.
// The clip's pelvis travels 2.59 m forward; the default model's legs are not the
// subject's, and the floor-contact model has no heel strike dynamics or flight phase.
TEST(RootMotion, CmuWalkTravelsForward) {
    std::ifstream f(std::string(MOCAP_SKELETON_TEST_DATA) + "/cmu_131_01_walk.bvh");
    std::stringstream ss;
    ss << f.rdbuf();
    const auto r = parse_bvh(ss.str());
    ASSERT_TRUE(r) << r.error;
    const BvhClip& clip = *r.clip;
    const BodyModel m = default_body_model();
    const auto sources = cmu_segment_sources();
    const auto map = map_bvh_to_model(clip, m, sources);
    ASSERT_TRUE(map);
    std::vector<Quat> qj(clip.joints.size());
    std::vector<Vec3> pj(clip.joints.size());
    auto qs = identity_quats();
    std::array<Vec3, kMaxSegments> ps{};
    FootContactRootTracker t(m);
    SkeletonPose pose;
    Vec3 truth0 = Vec3::Zero(), est0 = Vec3::Zero(), truth1 = Vec3::Zero(), est1 = Vec3::Zero();
    for (std::size_t fr = 0; fr < clip.frame_count; ++fr) {
        bvh_global_pose(clip, clip.frame(fr), 1.0, qj, pj);
        bvh_segment_pose(*map.mapping, qj, pj, qs, ps);
        const Vec3 root = t.update(m, qs, pose);
        if (fr == 0) {
            truth0 = ps[0];
            est0 = root;
        }
        truth1 = ps[0];
        est1 = root;
    }
    const Vec3 truth = truth1 - truth0;
    const Vec3 est = est1 - est0;
    ASSERT_GT(truth.x(), 2.5);  // the clip walks along ENU +x (BVH +Z)
    // Measured: 1.98 m of 2.59 m forward, 0.75 m sideways drift (the clip contains a deep
    // side lunge). Bounds leave room for numerical change only in that regime.
    EXPECT_GT(est.x(), 0.7 * truth.x());
    EXPECT_LT(est.x(), 1.1 * truth.x());
    EXPECT_LT(std::abs(est.y() - truth.y()), 1.0);
    EXPECT_LT(std::abs(est.z() - truth.z()), 0.1);
}

}  // namespace
}  // namespace mocap::skeleton
