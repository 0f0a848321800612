// forward_kinematics.hpp — segment orientations + model offsets -> joint positions.
//
// For every segment i (parents first, as a valid model stores them):
//   joint_position_m[i] = joint_position_m[parent] + q_world_segment[parent] · offset_m[i]
//   end_position_m[i]   = joint_position_m[i] + q_world_segment[i] · end_m[i]
// and the root's joint is placed at root_position_m (default: root_position(model), the
// T-pose pelvis height above the world origin). Positions are in metres, world axes (the
// same world as the orientations: ENU or heading-aligned, calibration.hpp).
// The root does not travel: callers that estimate travel (e.g. from foot contacts) pass it
// in root_position_m.
//
// Fixed arrays of kMaxSegments: no allocation. O(segments). Pure; thread-safe.
#pragma once

#include <array>
#include <span>

#include "core/frame.hpp"
#include "skeleton/body_model.hpp"

namespace mocap::skeleton {

struct KinematicPose {
    std::size_t segment_count = 0;
    std::array<Quat, kMaxSegments> q_world_segment = identity_quats();
    std::array<Vec3, kMaxSegments> joint_position_m = zero_vec3s();  ///< proximal joint of each segment
    std::array<Vec3, kMaxSegments> end_position_m = zero_vec3s();    ///< distal tip of each segment
};

/// (0, 0, model.root_height_m) plus the root's own offset.
Vec3 root_position(const BodyModel& model);

/// Fills `out` for a valid model; q_world_segment must hold model.size() orientations.
void forward_kinematics(const BodyModel& model, std::span<const Quat> q_world_segment, const Vec3& root_position_m,
                        KinematicPose& out);

}  // namespace mocap::skeleton
