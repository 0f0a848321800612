#include "skeleton/forward_kinematics.hpp"

#include <algorithm>
#include <cassert>

namespace mocap::skeleton {

Vec3 root_position(const BodyModel& model) {
    Vec3 p(0.0, 0.0, model.root_height_m);
    if (!model.segments.empty()) p += model.segments[0].offset_m;
    return p;
}

void forward_kinematics(const BodyModel& model, std::span<const Quat> q_world_segment, const Vec3& root_position_m,
                        KinematicPose& out) {
    const std::size_t n = std::min(model.size(), kMaxSegments);
    assert(q_world_segment.size() >= n);
    out.segment_count = n;
    for (std::size_t i = 0; i < n; ++i) {
        const SegmentDef& s = model.segments[i];
        const Quat& q = q_world_segment[i];
        out.q_world_segment[i] = q;
        if (s.parent < 0) {
            out.joint_position_m[i] = root_position_m;
        } else {
            const auto p = static_cast<std::size_t>(s.parent);
            out.joint_position_m[i] = out.joint_position_m[p] + out.q_world_segment[p]._transformVector(s.offset_m);
        }
        out.end_position_m[i] = out.joint_position_m[i] + q._transformVector(s.end_m);
    }
}

}  // namespace mocap::skeleton
