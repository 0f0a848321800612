// joint_angles.hpp — anatomical joint angles from segment orientations.
//
// The relative rotation of a joint is q_rel = conj(q_world_parent) ⊗ q_world_child (the
// child's frame in the parent's frame; identity in the T-pose, body_model.hpp). It is
// measured from the joint's anatomical neutral q_neutral (identity except for the
// shoulder, whose neutral is the arm hanging down: Rx(-90°) left, Rx(+90°) right):
//     q_anat = q_rel ⊗ conj(q_neutral)
// and decomposed into a Cardan sequence (euler.hpp: intrinsic, first axis fixed in the
// parent, last axis the child's long axis), following the ISB / Grood–Suntay idea
// (flexion about the medio-lateral axis first, rotation about the distal long axis last).
// Segment axes: x anterior, y left (medio-lateral), z superior (the long axis of the leg
// and of the hanging arm).
//
//   joint     parent -> child        sequence  flexion+          abduction+           rotation+
//   hip       pelvis -> thigh        Y X Z     thigh forward     thigh away from       internal (toes
//                                                                 the midline          turn inward)
//   knee      thigh  -> calf         Y X Z     foot backward     calf away (valgus)   internal
//   ankle     calf   -> foot         Y X Z     dorsiflexion      inversion (sole       internal
//                                              (toes up)          turns inward)       (adduction)
//   shoulder  trunk  -> upper arm    X Y Z     arm forward       arm sideways up      internal
//   elbow     upper arm -> forearm   Z X Y     flexion (from T-  forearm tip up in    pronation
//                                              pose: forward)    the T-pose (valgus)
//
// Signs are mirrored so that left and right read the same: flexion and abduction and
// rotation are positive for the same anatomical motion on both sides (about our axes,
// the x and z components change sign from left to right, y does not).
// The shoulder starts with abduction (frontal plane, as the arms rise into the T-pose),
// so the T-pose reads (flexion 0, abduction 90°, rotation 0); its sequence has gimbal lock
// only with the arm pointing straight forward or back (flexion ±90°). The elbow's neutral
// is the extended arm of the T-pose (palms down): flexion moves the forearm forward.
// Angles in radians, see euler.hpp for ranges. Pure functions, no allocation.
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/euler.hpp"

namespace mocap::skeleton {

enum class JointKind : std::uint8_t { kHip, kKnee, kAnkle, kShoulder, kElbow };
enum class Side : std::uint8_t { kLeft, kRight };

struct JointAngles {
    double flexion_rad = 0.0;
    double abduction_rad = 0.0;
    double rotation_rad = 0.0;
};

struct JointSpec {
    std::string name;  ///< e.g. "left_knee"
    JointKind kind = JointKind::kKnee;
    Side side = Side::kLeft;
    int parent_segment = -1;
    int child_segment = -1;
};

/// The ten joints of the default body (left/right hip, knee, ankle, shoulder, elbow) that
/// exist in `model` by the canonical segment names (body_model.hpp), in that order.
std::vector<JointSpec> default_joint_specs(const BodyModel& model);

/// conj(q_world_parent) ⊗ q_world_child.
Quat relative_rotation(const Quat& q_world_parent, const Quat& q_world_child);

/// Anatomical angles of one joint (table above).
JointAngles joint_angles(JointKind kind, Side side, const Quat& q_world_parent, const Quat& q_world_child);

/// Inverse of joint_angles: the child's orientation for given angles (for tests, poses
/// and simulators).
Quat child_orientation(JointKind kind, Side side, const Quat& q_world_parent, const JointAngles& angles);

/// Angles of every spec (out.size() >= specs.size()); a spec whose segments lie beyond
/// q_world_segment.size() gets zeros. No allocation.
void compute_joint_angles(std::span<const JointSpec> specs, std::span<const Quat> q_world_segment,
                          std::span<JointAngles> out);

}  // namespace mocap::skeleton
