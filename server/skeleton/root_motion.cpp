#include "skeleton/root_motion.hpp"

namespace mocap::skeleton {

FootContactRootTracker::FootContactRootTracker(const BodyModel& model, const RootMotionParams& params)
    : params_(params) {
    for (const auto name : {seg::kLeftFoot, seg::kRightFoot}) {
        const int i = model.index_of(name);
        if (i >= 0) feet_[foot_count_++] = i;
    }
    reset(root_position(model));
}

void FootContactRootTracker::reset(const Vec3& root_position_m) {
    root_m_ = root_position_m;
    contact_ = -1;
}

Vec3 FootContactRootTracker::candidate(const BodyModel& model, const KinematicPose& pose, int c) const {
    const auto foot = static_cast<std::size_t>(feet_[static_cast<std::size_t>(c / 3)]);
    switch (c % 3) {
        case 0:
            return pose.end_position_m[foot];
        case 1: {
            const Vec3& e = model.segments[foot].end_m;
            return pose.joint_position_m[foot] +
                   pose.q_world_segment[foot]._transformVector(Vec3(-e.x() / 3.0, 0.0, e.z()));
        }
        default:
            return pose.joint_position_m[foot];
    }
}

Vec3 FootContactRootTracker::update(const BodyModel& model, std::span<const Quat> q_world_segment, KinematicPose& out) {
    forward_kinematics(model, q_world_segment, root_m_, out);
    if (foot_count_ == 0) return root_m_;
    const int candidates = static_cast<int>(foot_count_) * 3;
    Vec3 shift = Vec3::Zero();
    if (contact_ >= 0 && params_.horizontal_travel) {
        const Vec3 p = candidate(model, out, contact_);
        shift.x() = contact_anchor_m_.x() - p.x();
        shift.y() = contact_anchor_m_.y() - p.y();
    }
    int lowest = 0;
    double lowest_z = candidate(model, out, 0).z();
    for (int c = 1; c < candidates; ++c) {
        const double z = candidate(model, out, c).z();
        if (z < lowest_z) {
            lowest_z = z;
            lowest = c;
        }
    }
    shift.z() = params_.floor_z_m - lowest_z;
    if (lowest != contact_) {
        contact_ = lowest;
        contact_anchor_m_ = candidate(model, out, lowest) + shift;
    }
    root_m_ += shift;
    for (std::size_t i = 0; i < out.segment_count; ++i) {
        out.joint_position_m[i] += shift;
        out.end_position_m[i] += shift;
    }
    return root_m_;
}

}  // namespace mocap::skeleton
