// bvh_outputs_fixture.hpp — shared helpers of the BVH output tests: the default body's
// encoder and poses with a distinct, known orientation per frame.
#pragma once

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "core/frame.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve::test {

/// Frame Time fixed at 0.01 s ([outputs] bvh_frame_time_s = 0.01).
inline BvhFrameEncoder default_encoder() {
    BvhOutputOptions o;
    o.frame_time_s = 0.01;
    return BvhFrameEncoder(skeleton::default_body_model(), o);
}

/// Frame Time measured from the frames (the default configuration).
inline BvhFrameEncoder measured_encoder() {
    return BvhFrameEncoder(skeleton::default_body_model(), {});
}

/// Frame k of a subject: every segment turned k degrees about z, root 1 m up; sampled every
/// `period_us` on the sink's clock.
inline void make_pose(std::uint32_t subject, std::uint64_t k, std::uint16_t segments, SubjectFrame& f,
                      skeleton::SkeletonPose& p, std::int64_t period_us = 10'000) {
    f = SubjectFrame{};
    f.subject_id = subject;
    f.sync = k;
    f.sample_us = static_cast<std::int64_t>(k) * period_us;
    f.segment_count = segments;
    p = skeleton::SkeletonPose{};
    p.segment_count = segments;
    const double half = 0.5 * static_cast<double>(k) * 3.14159265358979323846 / 180.0;
    for (std::size_t i = 0; i < segments; ++i)
        p.q_world_segment_wxyz[i] = {std::cos(half), 0.0, 0.0, std::sin(half)};
    p.position_m[0] = {0.0, 0.0, 1.0};
}

inline std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

}  // namespace mocap::serve::test
