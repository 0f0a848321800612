#include "serve/bvh_frame_encoder.hpp"

#include <array>
#include <cassert>
#include <cstdio>

namespace mocap::serve {

BvhFrameEncoder::BvhFrameEncoder(skeleton::BodyModel model, const BvhOutputOptions& options)
    : model_(std::move(model)),
      options_(options),
      hierarchy_(skeleton::bvh_hierarchy_text(model_, options_.write)),
      values_per_frame_(skeleton::bvh_values_per_frame(model_)) {}

std::string BvhFrameEncoder::frame_time_line(double measured_s) const {
    char buf[64];
    std::snprintf(buf, sizeof buf, "Frame Time: %.6f\n", fixed_frame_time() ? options_.frame_time_s : measured_s);
    return buf;
}

void BvhFrameEncoder::append_motion_line(const skeleton::SkeletonPose& pose, std::string& out) const {
    const std::size_t n = model_.size();
    assert(pose.segment_count == n);
    std::array<skeleton::Quat, kMaxSegments> q;
    for (std::size_t i = 0; i < n; ++i) {
        const auto& w = pose.q_world_segment_wxyz[i];
        q[i] = skeleton::Quat(w[0], w[1], w[2], w[3]);
    }
    const auto& p = pose.position_m[0];
    skeleton::append_bvh_motion_line(model_, options_.write, std::span<const skeleton::Quat>(q.data(), n),
                                     skeleton::Vec3(p[0], p[1], p[2]), out);
}

}  // namespace mocap::serve
