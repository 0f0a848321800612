// mocap-sim stream's motion sources: the still T-pose, continuity of the walk, and the BVH
// source reproducing the clip's mapped orientations.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "math/quaternion.hpp"
#include "sim/stream_motion.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::sim {
namespace {

double angle_between(const Quat& a, const Quat& b) {
    return math::angle_rad(math::conj(a) * b);
}

const std::string kWalkClip = std::string(MOCAP_MOTION_DIR) + "/cmu_131_01_walk.bvh";

TEST(StreamMotion, WalkStandsStillInTheTPoseThenMovesContinuously) {
    const auto model = skeleton::default_body_model();
    const StreamMotion walk = StreamMotion::walk(model, 2.0);
    BodyPose a, b;
    walk.pose(0.0, 0.7, Vec3(1, 2, 0), a);
    walk.pose(1.99, 0.7, Vec3(1, 2, 0), b);
    const Quat facing(std::cos(0.35), 0, 0, std::sin(0.35));
    for (std::size_t i = 0; i < model.size(); ++i) {
        EXPECT_LT(angle_between(a.q_earth_segment[i], facing), 1e-12) << model.segments[i].name;
        EXPECT_LT(angle_between(b.q_earth_segment[i], facing), 1e-12);
        EXPECT_LT((a.sensor_position_m[i] - b.sensor_position_m[i]).norm(), 1e-12);
    }
    // After the blend: every segment moves, nothing jumps (100 Hz steps), the heading turns.
    double max_step = 0.0, moved_thigh = 0.0;
    BodyPose prev;
    walk.pose(2.0, 0.0, Vec3::Zero(), prev);
    for (int k = 201; k <= 1200; ++k) {
        BodyPose cur;
        walk.pose(k * 0.01, 0.0, Vec3::Zero(), cur);
        for (std::size_t i = 0; i < model.size(); ++i) {
            max_step = std::max(max_step, angle_between(prev.q_earth_segment[i], cur.q_earth_segment[i]));
        }
        moved_thigh = std::max(moved_thigh, angle_between(cur.q_earth_segment[9], cur.q_earth_segment[0]));
        prev = cur;
    }
    EXPECT_LT(max_step, 5.0 * M_PI / 180.0);
    EXPECT_GT(moved_thigh, 15.0 * M_PI / 180.0) << "the hip flexes";
    const Vec3 fwd = math::rotate(prev.q_earth_segment[0], Vec3::UnitX());
    EXPECT_GT(std::abs(std::atan2(fwd.y(), fwd.x())), 60.0 * M_PI / 180.0) << "10 s on a 4 m circle turns > 90°";
    // Upper arm lowered from the T-pose: its long axis (model end_m, along +y for the left arm) points down.
    const Vec3 arm = math::rotate(prev.q_earth_segment[3], model.segments[3].end_m.normalized());
    EXPECT_LT(arm.z(), -0.8);
}

TEST(StreamMotion, BvhSourceReproducesTheMappedClip) {
    const auto model = skeleton::default_body_model();
    std::string error;
    const auto clip = StreamMotion::from_bvh_file(kWalkClip, model, 1.0, &error);
    ASSERT_TRUE(clip) << error;
    ASSERT_TRUE(clip->is_clip());
    const double ft = 0.008333;
    const double start = clip->calibrate_s() + clip->blend_s();  // fully blended from here
    std::array<Quat, kMaxSegments> q_clip, q_sim;
    Vec3 root_clip, root_sim;
    for (std::size_t f : {200u, 350u, 700u}) {
        const double tm = static_cast<double>(f) * ft;
        if (tm < clip->blend_s()) continue;
        clip->clip_frame(f, q_clip, &root_clip);
        clip->orientations(clip->calibrate_s() + tm, 0.0, Vec3::Zero(), q_sim, root_sim);
        for (std::size_t i = 0; i < model.size(); ++i) {
            EXPECT_LT(angle_between(q_clip[i], q_sim[i]), 1e-3) << model.segments[i].name << " frame " << f;
        }
    }
    // Between frames: the slerp of the neighbours.
    std::array<Quat, kMaxSegments> q0, q1;
    clip->clip_frame(400, q0, nullptr);
    clip->clip_frame(401, q1, nullptr);
    clip->orientations(clip->calibrate_s() + 400.5 * ft, 0.0, Vec3::Zero(), q_sim, root_sim);
    for (std::size_t i = 0; i < model.size(); ++i) {
        EXPECT_LT(angle_between(math::slerp(q0[i], q1[i], 0.5), q_sim[i]), 1e-3);
    }
    // Still T-pose first, facing the clip's first pelvis heading.
    clip->orientations(0.5, 0.0, Vec3::Zero(), q_sim, root_sim);
    clip->clip_frame(0, q0, nullptr);
    const Vec3 fwd = math::rotate(q0[0], Vec3::UnitX());
    const double h = std::atan2(fwd.y(), fwd.x());
    for (std::size_t i = 0; i < model.size(); ++i) {
        EXPECT_LT(angle_between(q_sim[i], Quat(std::cos(h / 2), 0, 0, std::sin(h / 2))), 1e-9);
    }
    // Looping (period = clip length - 0.3 s cross-fade) is no faster than the clip itself:
    // the largest 10 ms step around the loop point stays below the largest step inside the
    // first pass (the clip's own hands and feet reach ~15° per 10 ms), and the root is continuous.
    const double period = 994 * ft - 0.3;
    auto max_step_in = [&](double tm0, double tm1, double* root_jump) {
        double worst = 0.0;
        std::array<Quat, kMaxSegments> a, b;
        Vec3 ra, rb;
        clip->orientations(clip->calibrate_s() + tm0, 0.0, Vec3::Zero(), a, ra);
        for (double tm = tm0 + 0.01; tm <= tm1; tm += 0.01) {
            clip->orientations(clip->calibrate_s() + tm, 0.0, Vec3::Zero(), b, rb);
            for (std::size_t i = 0; i < model.size(); ++i)
                worst = std::max(worst, angle_between(a[i], b[i]));
            *root_jump = std::max(*root_jump, (rb - ra).norm());
            a = b;
            ra = rb;
        }
        return worst;
    };
    double jump_inside = 0.0, jump_loop = 0.0;
    const double inside = max_step_in(clip->blend_s(), period - 0.3, &jump_inside);
    const double at_loop = max_step_in(period - 0.3, period + 0.6, &jump_loop);
    const double second_loop = max_step_in(2 * period - 0.3, 2 * period + 0.6, &jump_loop);
    EXPECT_LE(at_loop, inside);
    EXPECT_LE(second_loop, inside);
    EXPECT_LT(jump_loop, 2.0 * jump_inside + 1e-3) << "root per 10 ms: inside the clip " << jump_inside;
    (void)start;
}

TEST(StreamMotion, BvhSourceReportsUnreadableFiles) {
    const auto model = skeleton::default_body_model();
    std::string error;
    EXPECT_FALSE(StreamMotion::from_bvh_file("/nonexistent/clip.bvh", model, 2.0, &error));
    EXPECT_NE(error.find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace mocap::sim
