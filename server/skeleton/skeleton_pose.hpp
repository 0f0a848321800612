// skeleton_pose.hpp — what the skeleton solver (pose_solver.hpp) hands to the outputs for
// one subject frame, next to the assembler's SubjectFrame: the calibrated skeleton pose.
//
// The skeleton component computes these values; the serve component only encodes them,
// so it needs this header but not the body model. Plain value type, no heap (docs/style.md,
// "Hot path never allocates").
#pragma once

#include <array>
#include <cstdint>

#include "core/frame.hpp"
#include "core/imu_sample.hpp"

namespace mocap::skeleton {

/// Most joint-angle values one frame may carry (three per segment).
inline constexpr std::size_t kMaxJointAngles = 3 * kMaxSegments;

/// kMaxSegments identity quaternions (w = 1): the pose of a segment nobody has set.
constexpr std::array<std::array<double, 4>, kMaxSegments> identity_quaternions() {
    std::array<std::array<double, 4>, kMaxSegments> out{};
    for (auto& q : out)
        q = {1.0, 0.0, 0.0, 0.0};
    return out;
}

/// Calibrated pose of one subject at one SYNC instant. Segment order is the order of
/// the skeleton description given to the server (ServeDescription::segments) and of
/// SubjectFrame::segments.
struct SkeletonPose {
    std::uint16_t segment_count = 0;  ///< must equal SubjectFrame::segment_count
    /// World-from-segment orientation after sensor-to-segment calibration, (w,x,y,z).
    std::array<std::array<double, 4>, kMaxSegments> q_world_segment_wxyz = identity_quaternions();
    /// Segment origin (its joint with the parent) in the world frame, metres.
    std::array<Vec3d, kMaxSegments> position_m{};
    /// Flag bits (SegmentFlags) OR-ed onto SubjectFrame::segments[i].flags, e.g.
    /// kSegmentCalibrated.
    std::array<std::uint8_t, kMaxSegments> extra_flags{};
    /// Joint angles in the order of ServeDescription::joint_angle_names, radians.
    std::uint16_t joint_angle_count = 0;
    std::array<double, kMaxJointAngles> joint_angles_rad{};
};

}  // namespace mocap::skeleton
