// bvh_write.hpp — BVH writing (reading and the clip types: bvh.hpp).
//
// Writing. The writer emits a BodyModel as HIERARCHY (joint names = segment names, OFFSETs
// in a configurable unit, centimetres by default; the root with 6 channels
// Xposition Yposition Zposition + 3 rotations, every other joint 3 rotations, one rotation
// order for all joints, ZXY by default; an End Site at every leaf from SegmentDef::end_m)
// and one MOTION line per frame from world segment orientations and the root position.
// The rest pose of a written file is the T-pose. A generic writer of a parsed clip exists
// for round trips.
//
// Thread-safety: pure functions on values. append_bvh_motion_line allocates only if `out`
// lacks capacity (it runs per frame per subject for the live BVH outputs).
#pragma once

#include <cstddef>
#include <span>
#include <string>

#include "skeleton/body_model.hpp"
#include "skeleton/bvh.hpp"
#include "skeleton/euler.hpp"

namespace mocap::skeleton {

/// Writes a parsed clip back as BVH text (6 decimals). parse_bvh(write_bvh(c)) == c to
/// within 5e-7 in every value.
std::string write_bvh(const BvhClip& clip);

struct BvhWriteOptions {
    double units_per_m = 100.0;  ///< OFFSET and root position unit: 100 = centimetres
    RotationOrder order{};       ///< for every joint; default ZXY
    int decimals = 4;            ///< digits after the point in MOTION values (degrees / unit)
};

/// "HIERARCHY\n" ... up to and including the root's closing "}\n". Model must be valid.
std::string bvh_hierarchy_text(const BodyModel& model, const BvhWriteOptions& options = {});
/// "MOTION\nFrames: N\nFrame Time: T\n".
std::string bvh_motion_header(std::size_t frames, double frame_time_s);
/// Values per MOTION line for this model: 6 + 3 × (segments − 1).
std::size_t bvh_values_per_frame(const BodyModel& model);
/// Appends one MOTION line (terminated by '\n') for world segment orientations
/// (q_world_segment[i] for model segment i; world = ENU or the heading-aligned body frame)
/// and the root joint position in metres (world axes).
void append_bvh_motion_line(const BodyModel& model, const BvhWriteOptions& options,
                            std::span<const Quat> q_world_segment, const Vec3& root_position_m, std::string& out);

}  // namespace mocap::skeleton
