// bvh_mapping.hpp — mapping a BVH skeleton (the CMU clips) onto a BodyModel: which joint
// drives which segment, the constant joint-to-segment rotations, a BodyModel with the
// clip's dimensions, and segment poses from a frame's global joint pose (bvh.hpp).
//
// Thread-safety: pure functions on values; bvh_segment_pose does not allocate.
#pragma once

#include <array>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "skeleton/body_model.hpp"
#include "skeleton/bvh.hpp"

namespace mocap::skeleton {

/// Where one model segment comes from: the first of `joints` present in the clip drives
/// the segment (its global orientation and position); the first of `tips` present gives
/// the segment's long axis in the BVH rest pose ("End Site" = that joint's End Site;
/// empty list = no long-axis correction, as for the pelvis).
struct BvhSegmentSource {
    std::string segment;
    std::vector<std::string> joints;
    std::vector<std::string> tips;
};

/// The 15 default segments from the CMU skeleton as converted for 3ds Max (the clips in
/// the shared motion data: Hips, lowerback, Chest, Chest2, Neck, Head, LeftShoulder,
/// LeftElbow, lhand, LeftHip, LeftKnee, LeftAnkle, LeftToe, ...), with the names of the
/// other common CMU conversion (Hips, Spine1, Head, LeftArm, LeftForeArm, LeftHand,
/// LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, ...) as fallbacks:
///   pelvis <- Hips;  trunk <- Chest2 (the joint the arms hang from, tip Neck);
///   head <- Head;  upper arm <- LeftArm|LeftShoulder (LeftArm first: in the second naming
///   LeftShoulder is the collar);  forearm <- LeftElbow|LeftForeArm;
///   hand <- lhand|LeftHand;  thigh <- LeftHip|LeftUpLeg;  calf <- LeftKnee|LeftLeg;
///   foot <- LeftAnkle|LeftFoot;  and the same on the right.
std::vector<BvhSegmentSource> cmu_segment_sources();

/// Per model segment: the driving BVH joint and the constant rotation q_joint_segment with
/// q_enu_segment = q_enu_joint ⊗ q_joint_segment. It turns the model's T-pose long axis
/// (SegmentDef::end_m) onto the joint's rest-pose bone direction (shortest arc), so that
/// segment orientations follow the model's frame convention (identity = T-pose). The CMU
/// rest pose has the arms down, so a CMU clip at rest yields the N-pose (calibration.hpp).
struct BvhSegmentMapping {
    std::size_t segment_count = 0;
    std::array<int, kMaxSegments> joint{};
    std::array<Quat, kMaxSegments> q_joint_segment = identity_quats();
    std::array<Vec3, kMaxSegments> rest_tip_enu = zero_vec3s();  ///< joint -> tip at rest, file units
};

struct BvhMappingResult {
    std::optional<BvhSegmentMapping> mapping;
    std::string error;  ///< names the segment or joint that could not be resolved
    explicit operator bool() const { return mapping.has_value(); }
};

/// Every model segment must have a source whose joint exists in the clip.
BvhMappingResult map_bvh_to_model(const BvhClip& clip, const BodyModel& model,
                                  std::span<const BvhSegmentSource> sources);

/// The model `base` (names, hierarchy, node ids, filters) with the clip's dimensions: each
/// segment's offset is its driving joint's rest position relative to the parent's driving
/// joint, turned into the parent's T-pose frame (conj(q_joint_segment) of the parent); each
/// end_m keeps the base direction with the clip's rest bone length (segments without a
/// tip keep base.end_m); root_height_m is the root joint's rest height above the lowest
/// rest point of the clip. Forward kinematics of the result with bvh_segment_pose()
/// orientations then reproduces the clip's limb joint positions (see the tests).
/// unit_m = metres per file unit. No validation beyond the mapping's.
BodyModel body_model_from_bvh(const BvhClip& clip, const BvhSegmentMapping& mapping, const BodyModel& base,
                              double unit_m);

/// Segment orientations (ENU) and segment origins (the driving joint's position, metres)
/// from one frame's global joint pose (bvh_global_pose). No allocation.
void bvh_segment_pose(const BvhSegmentMapping& mapping, std::span<const Quat> q_enu_joint,
                      std::span<const Vec3> p_enu_joint_m, std::span<Quat> q_enu_segment,
                      std::span<Vec3> p_enu_segment_m);

}  // namespace mocap::skeleton
