// body_model.hpp — the skeleton definition: segments, hierarchy, offsets, sensor nodes.
//
// Frames. Every segment has its own frame. In the reference pose (the T-pose: standing,
// arms horizontal to the sides, palms down, feet forward) every segment frame is aligned
// with the body frame: x forward, y to the subject's left, z up (right-handed). A segment's
// orientation q_world_segment is therefore the identity in the T-pose when the subject faces
// the world +x axis.
//
// Geometry (T-pose, metres, in the parent segment's frame):
//   offset_m  — this segment's proximal joint relative to the parent's proximal joint;
//   end_m     — this segment's distal point (tip) relative to its own proximal joint: the
//               neck for the trunk, the knee for the thigh, the toe for the foot. It gives the
//               segment's long axis (BVH End Site, forward kinematics tip, BVH mapping).
// The root (parent -1) is placed by forward kinematics; root_height_m is its height above
// the floor in the T-pose.
//
// Plain values, no invariants enforced by construction: fill the struct (the daemon does it
// from TOML), then call validate(); other skeleton functions assume a valid model.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "math/quaternion.hpp"

namespace mocap::skeleton {

using math::Quat;
using math::Vec3;

/// kMaxSegments identity quaternions (Eigen's default constructor leaves them unset).
inline std::array<Quat, kMaxSegments> identity_quats() {
    std::array<Quat, kMaxSegments> a;
    a.fill(Quat::Identity());
    return a;
}

/// kMaxSegments zero vectors.
inline std::array<Vec3, kMaxSegments> zero_vec3s() {
    std::array<Vec3, kMaxSegments> a;
    a.fill(Vec3::Zero());
    return a;
}

struct SegmentDef {
    std::string name;              ///< [A-Za-z0-9_]+, unique (also the BVH joint name)
    int parent = -1;               ///< index of the parent segment, -1 for the root
    Vec3 offset_m = Vec3::Zero();  ///< proximal joint in the parent's frame (T-pose), m
    Vec3 end_m = Vec3::Zero();     ///< distal tip in this segment's frame (T-pose), m
    int node_id = -1;              ///< CAN node id of the sensor on it (0..127), -1 = none
    std::string filter;            ///< orientation filter name for this segment's sensor
};

struct BodyModel {
    std::vector<SegmentDef> segments;
    double root_height_m = 0.0;  ///< root joint height above the floor in the T-pose, m

    std::size_t size() const { return segments.size(); }
    /// Index of the segment with this name, -1 if none. O(n).
    int index_of(std::string_view name) const;
};

/// Canonical names of the default body; joint_angles and bvh_mapping look segments up
/// by these names.
namespace seg {
inline constexpr std::string_view kPelvis = "pelvis";
inline constexpr std::string_view kTrunk = "trunk";
inline constexpr std::string_view kHead = "head";
inline constexpr std::string_view kLeftUpperArm = "left_upper_arm";
inline constexpr std::string_view kLeftForearm = "left_forearm";
inline constexpr std::string_view kLeftHand = "left_hand";
inline constexpr std::string_view kRightUpperArm = "right_upper_arm";
inline constexpr std::string_view kRightForearm = "right_forearm";
inline constexpr std::string_view kRightHand = "right_hand";
inline constexpr std::string_view kLeftThigh = "left_thigh";
inline constexpr std::string_view kLeftCalf = "left_calf";
inline constexpr std::string_view kLeftFoot = "left_foot";
inline constexpr std::string_view kRightThigh = "right_thigh";
inline constexpr std::string_view kRightCalf = "right_calf";
inline constexpr std::string_view kRightFoot = "right_foot";
}  // namespace seg

/// The seed system's 15-segment body: pelvis (root); trunk (lumbar spine), head; left and
/// right upper arm, forearm, hand; left and right thigh, calf (shank), foot — in that
/// order, node ids 1..15 in that order, every filter = default_filter.
///
/// Dimensions are Winter's anthropometric segment-length ratios (Winter, Biomechanics and
/// Motor Control of Human Movement, 4th ed., fig. 4.1) times height_m: hip-joint height
/// 0.530 H, shoulder height 0.818 H, chin/neck 0.870 H, head 0.130 H, shoulder width
/// 0.259 H, hip width 0.191 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, thigh
/// 0.245 H, shank 0.246 H, ankle height 0.039 H, foot length 0.152 H (ankle to toe taken as
/// 0.75 of it). The lumbar joint (trunk origin) is assumed 0.100 H above the hip centre.
/// The pelvis origin is the midpoint of the hip joints, so root_height_m = 0.530 H.
BodyModel default_body_model(double height_m = 1.75, std::string_view default_filter = "csmo");

/// Checks the model: 1..kMaxSegments segments; names non-empty, [A-Za-z0-9_]+, at most 64
/// characters, unique; exactly one root and it is segment 0; every parent index in range
/// and smaller than the child's index (parents before children, hence acyclic); node ids in
/// -1..127 and unique (-1 may repeat); offsets finite and shorter than 5 m; root height
/// finite. Returns every problem found as one message each; empty means valid.
std::vector<std::string> validate(const BodyModel& model);

}  // namespace mocap::skeleton
