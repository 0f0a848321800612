#include "skeleton/root_motion.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "skeleton/bvh_mapping.hpp"

namespace mocap::skeleton {
namespace {

TEST(RootMotion, StandingStillStaysPutOnTheFloor) {
    const BodyModel m = default_body_model();
    FootContactRootTracker t(m);
    KinematicPose pose;
    const auto q = identity_quats();
    for (int f = 0; f < 100; ++f)
        t.update(m, q, pose);
    EXPECT_LT((pose.joint_position_m[0] - root_position(m)).norm(), 1e-12);
    EXPECT_NEAR(pose.end_position_m[static_cast<std::size_t>(m.index_of(seg::kLeftFoot))].z(), 0.0, 1e-12);
}

TEST(RootMotion, KneeBendLowersThePelvis) {
    const BodyModel m = default_body_model();
    FootContactRootTracker t(m);
    KinematicPose pose;
    auto q = identity_quats();
    // Squat-like: thighs forward 40°, calves upright, feet flat: the pelvis drops.
    const Quat thigh(Eigen::AngleAxisd(-40 * M_PI / 180, Vec3::UnitY()));
    for (const auto n : {seg::kLeftThigh, seg::kRightThigh})
        q[static_cast<std::size_t>(m.index_of(n))] = thigh;
    const Vec3 root = t.update(m, q, pose);
    const double thigh_len = 0.245 * 1.75;
    EXPECT_NEAR(root.z(), m.root_height_m - thigh_len * (1 - std::cos(40 * M_PI / 180)), 1e-9);
}

// Real walk: segment orientations from the CMU clip drive a 15-segment model; the root
// is moved by foot contacts only. Returns (estimated, true) pelvis displacement.
std::pair<Vec3, Vec3> cmu_walk_travel(bool clip_dimensions) {
    std::ifstream f(std::string(MOCAP_SKELETON_TEST_DATA) + "/cmu_131_01_walk.bvh");
    std::stringstream ss;
    ss << f.rdbuf();
    const auto r = parse_bvh(ss.str());
    EXPECT_TRUE(r) << r.error;
    if (!r) return {};
    const BvhClip& clip = *r.clip;
    const auto sources = cmu_segment_sources();
    const auto map = map_bvh_to_model(clip, default_body_model(), sources);
    EXPECT_TRUE(map);
    if (!map) return {};
    const BodyModel m =
        clip_dimensions ? body_model_from_bvh(clip, *map.mapping, default_body_model(), 1.0) : default_body_model();
    std::vector<Quat> qj(clip.joints.size());
    std::vector<Vec3> pj(clip.joints.size());
    auto qs = identity_quats();
    auto ps = zero_vec3s();
    FootContactRootTracker t(m);
    KinematicPose pose;
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
    return {est1 - est0, truth1 - truth0};
}

// With the subject's own segment lengths the contact model reproduces the walk: measured
// 2.595 m of 2.589 m forward, 2 cm sideways.
TEST(RootMotion, CmuWalkWithClipDimensionsTravelsLikeTheClip) {
    const auto [est, truth] = cmu_walk_travel(true);
    ASSERT_GT(truth.x(), 2.5);  // the clip walks along ENU +x (BVH +Z)
    EXPECT_NEAR(est.x(), truth.x(), 0.05 * truth.x());
    EXPECT_LT(std::abs(est.y() - truth.y()), 0.1);
    EXPECT_LT(std::abs(est.z() - truth.z()), 0.05);
}

// With the default (Winter, 1.75 m) body the legs are not the subject's: measured 1.98 m
// forward and 0.9 m sideways drift (the clip contains a deep side lunge).
TEST(RootMotion, CmuWalkWithDefaultBodyTravelsForward) {
    const auto [est, truth] = cmu_walk_travel(false);
    EXPECT_GT(est.x(), 0.7 * truth.x());
    EXPECT_LT(est.x(), 1.1 * truth.x());
    EXPECT_LT(std::abs(est.y() - truth.y()), 1.0);
    EXPECT_LT(std::abs(est.z() - truth.z()), 0.1);
}

}  // namespace
}  // namespace mocap::skeleton
