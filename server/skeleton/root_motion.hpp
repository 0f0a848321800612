// root_motion.hpp — root (pelvis) translation from foot contacts.
//
// Inertial sensors give orientations, not positions. The root is moved by assuming that
// the lowest foot point touches the floor and does not slide while it stays the lowest:
//   1. forward kinematics with last frame's root position;
//   2. if last frame's contact point is still a candidate, shift the root horizontally so
//      that point keeps the floor position it had when it became the contact;
//   3. the lowest candidate point becomes (or stays) the contact; a new contact records
//      its current horizontal position;
//   4. shift the root vertically so the lowest point is at floor_z_m.
// Candidates per foot segment: its tip (toe, SegmentDef::end_m) and a heel point
// ankle + q_foot · (−end_m.x / 3, 0, end_m.z) (the model's ankle sits at a quarter of the
// foot length from the heel: body_model.hpp), and the ankle joint itself.
// Limits (stated, not hidden): no flight phase (during a jump the lowest foot is pinned
// to the floor), flat level floor, no slipping; travel scales with the model's leg
// lengths, so a model whose legs differ from the subject's walks too far or too short.
// Measured on the CMU walk (tests/skeleton/root_motion_test.cpp): 2.595 m for the clip's
// 2.589 m with the subject's own segment lengths (body_model_from_bvh), 1.98 m with the
// default 1.75 m body; on the CMU hop (flight phases) 2.93 m for 3.27 m.
//
// Fixed arrays, no allocation, O(segments) per frame. One per subject; not thread-safe.
#pragma once

#include <array>
#include <span>
#include <string_view>

#include "skeleton/forward_kinematics.hpp"

namespace mocap::skeleton {

struct RootMotionParams {
    double floor_z_m = 0.0;
    bool horizontal_travel = true;  ///< false: root stays above its start, only height adapts
};

class FootContactRootTracker {
public:
    /// Feet are the model segments named seg::kLeftFoot / seg::kRightFoot; without them the
    /// root stays at its start position.
    explicit FootContactRootTracker(const BodyModel& model, const RootMotionParams& params = {});

    /// Restarts at a root position (default: root_position(model) at the origin).
    void reset(const Vec3& root_position_m);

    /// Solves one frame: fills `out` (forward kinematics at the new root) and returns the
    /// new root position (metres, world axes).
    Vec3 update(const BodyModel& model, std::span<const Quat> q_world_segment, KinematicPose& out);

    /// Index of the current contact candidate (foot * 3 + {0 toe, 1 heel, 2 ankle}), -1 none.
    int contact() const { return contact_; }

private:
    Vec3 candidate(const BodyModel& model, const KinematicPose& pose, int c) const;

    RootMotionParams params_;
    std::array<int, 2> feet_{-1, -1};
    std::size_t foot_count_ = 0;
    Vec3 root_m_ = Vec3::Zero();
    int contact_ = -1;
    Vec3 contact_anchor_m_ = Vec3::Zero();
};

}  // namespace mocap::skeleton
