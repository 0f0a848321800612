// bvh_frame_encoder.hpp — one body model's BVH text: the HIERARCHY once, one MOTION line
// per skeleton::SkeletonPose. Shared by the live BVH service, the BVH file recorder and replay, so
// every BVH mocapd writes is byte-for-byte the same encoding.
//
// Encoding (skeleton/bvh.hpp): joint names = segment names, OFFSETs and root position in
// `units_per_m` (centimetres by default), the root with 6 channels, every other joint 3,
// rotation order `order` (ZXY by default) for every joint, BVH Y-up axes, degrees.
// A MOTION line holds values_per_frame() numbers: root position (the pose's root segment
// origin, skeleton::SkeletonPose::position_m[0]) then every joint's local rotation.
//
// Thread-safety: const after construction; any number of threads may encode at once.
// Cost: one line is O(segments) trig plus fixed-point formatting (~2-4 µs for 15 segments);
// it allocates only when `out` lacks capacity.
#pragma once

#include <cstddef>
#include <string>

#include "serve/bvh_text.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/bvh_write.hpp"
#include "skeleton/skeleton_pose.hpp"

namespace mocap::serve {

struct BvhOutputOptions {
    skeleton::BvhWriteOptions write{};  ///< unit, rotation order, decimals
    /// "Frame Time:" when set ([outputs] bvh_frame_time_s); 0 = the interval the subject is
    /// actually sampled at, measured from its frames (serve/frame_interval.hpp).
    double frame_time_s = 0.0;
};

class BvhFrameEncoder {
public:
    /// `model` must be valid (skeleton::validate); its segment order is the pose's.
    BvhFrameEncoder(skeleton::BodyModel model, const BvhOutputOptions& options);

    /// "HIERARCHY\n" ... the root's closing "}\n".
    [[nodiscard]] const std::string& hierarchy() const { return hierarchy_; }
    /// Numbers per MOTION line: 6 + 3 × (segments − 1).
    [[nodiscard]] std::size_t values_per_frame() const { return values_per_frame_; }
    [[nodiscard]] const BvhOutputOptions& options() const { return options_; }
    [[nodiscard]] const skeleton::BodyModel& model() const { return model_; }
    /// A fixed Frame Time was configured (options().frame_time_s > 0).
    [[nodiscard]] bool fixed_frame_time() const { return options_.frame_time_s > 0.0; }
    /// "Frame Time: 0.010000\n": the configured value, else `measured_s`.
    [[nodiscard]] std::string frame_time_line(double measured_s) const;

    /// Appends one '\n'-terminated MOTION line for `pose` (pose.segment_count must equal
    /// the model's segment count; asserted).
    void append_motion_line(const skeleton::SkeletonPose& pose, std::string& out) const;

private:
    skeleton::BodyModel model_;
    BvhOutputOptions options_;
    std::string hierarchy_;
    std::size_t values_per_frame_ = 0;
};

}  // namespace mocap::serve
