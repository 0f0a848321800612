// vmc_rig.hpp — the body model as a Unity humanoid for the VMC protocol (docs/outputs.md,
// "VMC (live link to Unity, Blender, VTuber apps)"): which segment drives which
// `HumanBodyBones` bone, and the conversion of one SkeletonPose into the local bone
// rotations and positions a VMC receiver applies, in Unity's frame.
//
// Frames. Ours: x forward, y left, z up, right-handed (docs/design.md, "Quaternions and
// frames"); every q_world_segment is the identity in the T-pose. Unity: x right, y up,
// z forward, left-handed; a humanoid's normalised bones have identity local rotations in its
// T-pose. The change of axes u = M v with M = [[0,-1,0],[0,0,1],[1,0,0]] (det −1) maps a
// position (x, y, z) to (−y, z, x) and a rotation R to M R Mᵀ, i.e. the quaternion
// (w, x, y, z) to Unity's (x, y, z, w) = (y, −z, −x, w): the vector part turns as a
// pseudovector (det M · M v).
//
// Hierarchy. Bones we do not solve are not sent; a receiver keeps them at rest (identity).
// A mapped segment's local rotation is therefore taken relative to its nearest mapped
// ancestor segment, whose bone must be its bone's nearest mapped humanoid ancestor (checked
// by build()), so that composing the received local rotations down Unity's humanoid
// hierarchy (unsent bones as identity) gives back every segment's world orientation.
// Root: "root" at the pelvis projected on the floor (y = 0), identity rotation; Hips: local
// position (0, pelvis height, 0) and the pelvis's world rotation.
//
// Thread-safety: const after build(); convert() may run on any thread. Cost: convert() is
// one quaternion product per bone (~0.2 µs for 15 bones); no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "math/quaternion.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

/// One of Unity's HumanBodyBones: its name and its parent in the humanoid hierarchy
/// (index into humanoid_bones(), -1 for Hips).
struct HumanoidBone {
    std::string_view name;
    int parent;
};

/// Every HumanBodyBones bone (Unity's enum order, LastBone excluded).
std::span<const HumanoidBone> humanoid_bones();
/// Index of a bone in humanoid_bones(), -1 if `name` is none.
int humanoid_bone_index(std::string_view name);

/// The default body's segments (skeleton::seg) and their bones, used when no [vmc.bones]
/// mapping is configured: pelvis Hips, trunk Spine, head Head, upper arm/forearm/hand
/// UpperArm/LowerArm/Hand, thigh/calf/foot UpperLeg/LowerLeg/Foot.
std::span<const std::pair<std::string_view, std::string_view>> default_humanoid_map();

/// Our body frame -> Unity's (see the header comment).
math::Vec3 unity_from_body(const math::Vec3& v);
math::Quat unity_from_body(const math::Quat& q);

/// One bone as VMC sends it: Unity frame, metres, quaternion (x, y, z, w).
struct VmcBonePose {
    std::array<float, 3> position{};
    std::array<float, 4> rotation_xyzw{0.0f, 0.0f, 0.0f, 1.0f};
};

/// One frame for /VMC/Ext/Root/Pos and /VMC/Ext/Bone/Pos; bones in VmcRig::bone order.
struct VmcPose {
    VmcBonePose root;
    std::size_t bone_count = 0;
    std::array<VmcBonePose, kMaxSegments> bones{};
};

class VmcRig {
public:
    /// `map`: (segment name, HumanBodyBones name) pairs; empty = default_humanoid_map() for
    /// the segments the model has. nullopt + *error (naming the segment or bone) when a segment
    /// or bone name is unknown, a bone is used twice, the root segment is not Hips, or a bone's
    /// nearest mapped humanoid ancestor is not the bone of its segment's nearest mapped
    /// ancestor. `model` must be valid (skeleton::validate).
    static std::optional<VmcRig> build(const skeleton::BodyModel& model,
                                       const std::vector<std::pair<std::string, std::string>>& map, std::string* error);

    [[nodiscard]] std::size_t bone_count() const { return bones_.size(); }
    /// HumanBodyBones name of bone i (bones in segment order).
    [[nodiscard]] std::string_view bone_name(std::size_t i) const { return humanoid_bones()[bones_[i].bone].name; }
    /// Segment index of bone i.
    [[nodiscard]] int bone_segment(std::size_t i) const { return bones_[i].segment; }
    /// Names of the segments no bone carries (not sent).
    [[nodiscard]] const std::vector<std::string>& skipped_segments() const { return skipped_; }

    /// `pose` of the model given to build(). Root and one entry per bone; no allocation.
    void convert(const skeleton::SkeletonPose& pose, VmcPose& out) const;

private:
    struct Bone {
        int segment = 0;
        int ancestor = -1;  ///< nearest mapped ancestor segment; -1 for Hips (the root)
        int bone = 0;       ///< index into humanoid_bones()
        VmcBonePose rest;   ///< local position (Unity frame, m) from the ancestor at rest
    };
    std::vector<Bone> bones_;
    std::vector<std::string> skipped_;
};

}  // namespace mocap::serve
