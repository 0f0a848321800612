// stream_motion.cpp — why: the walk is written as joint angles scaled by one blend weight, so
// the T-pose (weight 0) and the gait share one formula and every orientation is continuous;
// the root travels along a circle parameterised by distance, so position and heading stay
// analytic (no integration state) and pose(t) can be evaluated at any t in any order.
#include "sim/stream_motion.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "math/quaternion.hpp"
#include "skeleton/forward_kinematics.hpp"

namespace mocap::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kStrideHz = 0.9;  // strides (left + right step) per second
constexpr double kWalkSpeedM_S = 1.2;
constexpr double kCircleRadiusM = 4.0;
constexpr double kLoopFadeS = 0.3;  // BVH loop cross-fade

Quat rot_x(double a) {
    return Quat(std::cos(a / 2), std::sin(a / 2), 0, 0);
}
Quat rot_y(double a) {
    return Quat(std::cos(a / 2), 0, std::sin(a / 2), 0);
}
Quat rot_z(double a) {
    return Quat(std::cos(a / 2), 0, 0, std::sin(a / 2));
}

double smoothstep(double u) {
    u = std::clamp(u, 0.0, 1.0);
    return u * u * (3.0 - 2.0 * u);
}
// ∫0^u smoothstep = u³ - u⁴/2 (for u in [0, 1]).
double smoothstep_integral(double u) {
    if (u <= 0.0) return 0.0;
    if (u >= 1.0) return 0.5 + (u - 1.0);
    return u * u * u - 0.5 * u * u * u * u;
}

double heading_of(const Quat& q) {
    const Vec3 x = math::rotate(q, Vec3::UnitX());
    return std::atan2(x.y(), x.x());
}

}  // namespace

StreamMotion::StreamMotion(const skeleton::BodyModel& model, double calibrate_s)
    : model_(model), calibrate_s_(calibrate_s) {
    namespace seg = skeleton::seg;
    walk_.pelvis = model_.index_of(seg::kPelvis);
    walk_.trunk = model_.index_of(seg::kTrunk);
    walk_.head = model_.index_of(seg::kHead);
    walk_.upper_arm[0] = model_.index_of(seg::kLeftUpperArm);
    walk_.upper_arm[1] = model_.index_of(seg::kRightUpperArm);
    walk_.forearm[0] = model_.index_of(seg::kLeftForearm);
    walk_.forearm[1] = model_.index_of(seg::kRightForearm);
    walk_.hand[0] = model_.index_of(seg::kLeftHand);
    walk_.hand[1] = model_.index_of(seg::kRightHand);
    walk_.thigh[0] = model_.index_of(seg::kLeftThigh);
    walk_.thigh[1] = model_.index_of(seg::kRightThigh);
    walk_.calf[0] = model_.index_of(seg::kLeftCalf);
    walk_.calf[1] = model_.index_of(seg::kRightCalf);
    walk_.foot[0] = model_.index_of(seg::kLeftFoot);
    walk_.foot[1] = model_.index_of(seg::kRightFoot);
}

StreamMotion StreamMotion::walk(const skeleton::BodyModel& model, double calibrate_s) {
    return StreamMotion(model, calibrate_s);
}

std::optional<StreamMotion> StreamMotion::from_bvh_file(const std::string& path, const skeleton::BodyModel& model,
                                                        double calibrate_s, std::string* error) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        *error = "cannot open " + path;
        return std::nullopt;
    }
    std::ostringstream text;
    text << in.rdbuf();
    auto parsed = skeleton::parse_bvh(text.str());
    if (!parsed) {
        *error = path + ": " + parsed.error;
        return std::nullopt;
    }
    if (parsed.clip->frame_count < 2 || !(parsed.clip->frame_time_s > 0.0)) {
        *error = path + ": a clip needs at least two frames and a positive frame time";
        return std::nullopt;
    }
    const auto sources = skeleton::cmu_segment_sources();
    auto mapped = skeleton::map_bvh_to_model(*parsed.clip, model, sources);
    if (!mapped) {
        *error = path + ": " + mapped.error;
        return std::nullopt;
    }
    const double period_s = static_cast<double>(parsed.clip->frame_count - 1) * parsed.clip->frame_time_s;
    if (period_s <= 2.0 * kLoopFadeS) {
        *error = path + ": the clip is too short to loop (needs more than 0.6 s)";
        return std::nullopt;
    }
    StreamMotion m(model, calibrate_s);
    m.clip_ = std::move(*parsed.clip);
    m.mapping_ = *mapped.mapping;
    std::array<Quat, kMaxSegments> q;
    Vec3 root0, root_end;
    m.clip_frame(0, q, &root0);
    m.clip_heading_rad_ = heading_of(q[0]);
    m.clip_root0_m_ = root0;
    // Root displacement over one loop period P = T - fade (the loop restarts at P).
    m.clip_at(period_s - kLoopFadeS, q, root_end);
    m.clip_loop_shift_m_ = Vec3(root_end.x() - root0.x(), root_end.y() - root0.y(), 0.0);
    return m;
}

void StreamMotion::clip_frame(std::size_t f, std::array<Quat, kMaxSegments>& q_enu_segment, Vec3* root_m) const {
    const skeleton::BvhClip& clip = *clip_;
    std::array<Quat, 256> q_joint;
    std::array<Vec3, 256> p_joint;
    const std::size_t n = clip.joints.size();
    skeleton::bvh_global_pose(clip, clip.frame(f), 1.0, std::span(q_joint.data(), n), std::span(p_joint.data(), n));
    std::array<Vec3, kMaxSegments> p_seg = skeleton::zero_vec3s();
    skeleton::bvh_segment_pose(
        mapping_, std::span<const Quat>(q_joint.data(), n), std::span<const Vec3>(p_joint.data(), n),
        std::span(q_enu_segment.data(), mapping_.segment_count), std::span(p_seg.data(), mapping_.segment_count));
    if (root_m != nullptr) *root_m = p_seg[0];
}

// The clip at time clip_t_s in [0, T]: slerp between the neighbouring frames.
void StreamMotion::clip_at(double clip_t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const {
    const skeleton::BvhClip& clip = *clip_;
    const double pos = std::clamp(clip_t_s / clip.frame_time_s, 0.0, static_cast<double>(clip.frame_count - 1));
    const auto f0 = std::min(static_cast<std::size_t>(pos), clip.frame_count - 2);
    const double a = pos - static_cast<double>(f0);
    std::array<Quat, kMaxSegments> q1;
    Vec3 r1;
    clip_frame(f0, q, &root);
    clip_frame(f0 + 1, q1, &r1);
    for (std::size_t i = 0; i < mapping_.segment_count; ++i)
        q[i] = math::slerp(q[i], q1[i], a);
    root = (1.0 - a) * root + a * r1;
}

void StreamMotion::clip_orientations(double t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const {
    const double tm = std::max(0.0, t_s - calibrate_s_);
    const double T = static_cast<double>(clip_->frame_count - 1) * clip_->frame_time_s;
    const double P = T - kLoopFadeS;  // loop period: the last fade window overlaps the next start
    const double loops = std::floor(tm / P);
    const double tau = tm - loops * P;
    clip_at(tau, q, root);
    if (loops >= 1.0 && tau < kLoopFadeS) {
        // Fade from the end of the previous loop into the start of this one.
        std::array<Quat, kMaxSegments> q_end;
        Vec3 root_end;
        clip_at(tau + P, q_end, root_end);
        const double a = tau / kLoopFadeS;
        for (std::size_t i = 0; i < mapping_.segment_count; ++i)
            q[i] = math::slerp(q_end[i], q[i], a);
        root = (1.0 - a) * (root_end - clip_loop_shift_m_) + a * root;
    }
    root += loops * clip_loop_shift_m_;
    // Blend from the still T-pose (facing the clip's first heading) into the clip.
    const double w = smoothstep(tm / blend_s_);
    const Quat facing = rot_z(clip_heading_rad_);
    const Vec3 t_pose_root(clip_root0_m_.x(), clip_root0_m_.y(), model_.root_height_m);
    const Vec3 clip_root(root.x(), root.y(), model_.root_height_m + (root.z() - clip_root0_m_.z()));
    for (std::size_t i = 0; i < mapping_.segment_count; ++i)
        q[i] = math::slerp(facing, q[i], w);
    root = (1.0 - w) * t_pose_root + w * clip_root - Vec3(clip_root0_m_.x(), clip_root0_m_.y(), 0.0);
}

void StreamMotion::walk_orientations(double t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const {
    const double tm = std::max(0.0, t_s - calibrate_s_);
    const double w = smoothstep(tm / blend_s_);
    const double travel_m = kWalkSpeedM_S * blend_s_ * smoothstep_integral(tm / blend_s_);
    const double psi = travel_m / kCircleRadiusM;  // heading turns left along the circle
    const double phi = 2.0 * std::numbers::pi * kStrideHz * tm;
    const Quat heading = rot_z(psi);

    for (std::size_t i = 0; i < model_.size(); ++i)
        q[i] = heading;
    const double pelvis_yaw = w * 5.0 * kDeg * std::sin(phi);
    const Quat base = heading * rot_z(pelvis_yaw);
    auto set = [&](int index, const Quat& value) {
        if (index >= 0) q[static_cast<std::size_t>(index)] = value.normalized();
    };
    set(walk_.pelvis, base * rot_x(w * 4.0 * kDeg * std::sin(phi)));
    const Quat trunk = heading * rot_z(-0.8 * pelvis_yaw) * rot_y(w * (6.0 * kDeg + 1.5 * kDeg * std::sin(2 * phi)));
    set(walk_.trunk, trunk);
    set(walk_.head, trunk * rot_y(w * (-4.0 * kDeg + 2.0 * kDeg * std::sin(2 * phi))));
    const Quat trunk_yaw = heading * rot_z(-0.8 * pelvis_yaw);
    for (int side = 0; side < 2; ++side) {
        const double phase = phi + side * std::numbers::pi;            // right leg half a stride later
        const double hip = w * (5.0 + 22.0 * std::sin(phase)) * kDeg;  // flexion: thigh forward
        const double knee = w * (35.0 + 30.0 * std::sin(phase - 0.5 * std::numbers::pi)) * kDeg;
        const double ankle = w * 10.0 * kDeg * std::sin(phase + std::numbers::pi / 3.0);
        const Quat thigh = base * rot_y(-hip);
        const Quat calf = thigh * rot_y(knee);
        set(walk_.thigh[side], thigh);
        set(walk_.calf[side], calf);
        set(walk_.foot[side], base * rot_y(-ankle));  // the foot stays near level
        // Arms: lowered from the T-pose, swinging against the leg of the same side.
        const double lower = w * 80.0 * kDeg * (side == 0 ? -1.0 : 1.0);
        const double swing = w * 18.0 * kDeg * std::sin(phase);
        const double elbow = w * (20.0 + 10.0 * std::sin(phase)) * kDeg;
        set(walk_.upper_arm[side], trunk_yaw * rot_y(swing) * rot_x(lower));
        const Quat forearm = trunk_yaw * rot_y(swing - elbow) * rot_x(lower);
        set(walk_.forearm[side], forearm);
        set(walk_.hand[side], forearm);
    }
    // Circle through the start point, tangent to the initial heading (+x).
    root = Vec3(kCircleRadiusM * std::sin(psi), kCircleRadiusM * (1.0 - std::cos(psi)),
                model_.root_height_m - w * (0.02 + 0.02 * std::cos(2.0 * phi)));
}

void StreamMotion::orientations(double t_s, double heading_rad, const Vec3& origin_m,
                                std::array<Quat, kMaxSegments>& q_earth_segment, Vec3& root_m) const {
    if (clip_) {
        clip_orientations(t_s, q_earth_segment, root_m);
    } else {
        walk_orientations(t_s, q_earth_segment, root_m);
    }
    const Quat turn = rot_z(heading_rad);
    for (std::size_t i = 0; i < model_.size(); ++i)
        q_earth_segment[i] = (turn * q_earth_segment[i]).normalized();
    root_m = origin_m + math::rotate(turn, root_m);
}

void StreamMotion::pose(double t_s, double heading_rad, const Vec3& origin_m, BodyPose& out) const {
    Vec3 root;
    orientations(t_s, heading_rad, origin_m, out.q_earth_segment, root);
    out.segment_count = model_.size();
    skeleton::KinematicPose fk;
    skeleton::forward_kinematics(model_, std::span<const Quat>(out.q_earth_segment.data(), model_.size()), root, fk);
    for (std::size_t i = 0; i < model_.size(); ++i) {
        out.sensor_position_m[i] = 0.5 * (fk.joint_position_m[i] + fk.end_position_m[i]);
    }
}

}  // namespace mocap::sim
