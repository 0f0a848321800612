// stream_motion.hpp — whole-body motion for `mocap-sim stream`: every segment's global
// orientation q_earth_segment(t) and its sensor's position, from a built-in walk or a BVH clip.
//
// Timeline (both sources): the subject stands still in the T-pose (every segment = the
// heading rotation Rz(heading), see body_model.hpp) for calibrate_s seconds, then blends
// into the motion over blend_s seconds (smoothstep weight; orientations by slerp, joint
// angles / root travel scaled), then moves.
//   walk  procedural gait at 0.9 strides/s: hip/knee/ankle flexion sinusoids, arms lowered
//         from the T-pose swinging against the legs, elbow flexion, pelvis yaw/roll/bob,
//         trunk counter-rotation and lean; the root walks a circle of radius 4 m at 1.2 m/s,
//         so the heading turns steadily (~17 °/s).
//   BVH   a clip (parse_bvh + map_bvh_to_model with cmu_segment_sources()), looped with a
//         0.3 s slerp cross-fade from its end to its start, interpolated between frames by
//         slerp; the root translation is made continuous across loops. The T-pose faces the
//         clip's first-frame pelvis heading.
// Positions: forward kinematics of the body model (skeleton/forward_kinematics.hpp) from
// the orientations and the root position; a sensor sits at the middle of its segment
// (between proximal joint and tip).
//
// Units: s, m, ENU (x east, y north, z up). Thread-safety: const methods are pure; one
// instance may be shared by threads. Cost: pose() is O(segments) (walk) or
// O(BVH joints) (clip), no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <string>

#include "core/frame.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/bvh_mapping.hpp"

namespace mocap::sim {

using skeleton::Quat;
using skeleton::Vec3;

/// One instant of one subject.
struct BodyPose {
    std::size_t segment_count = 0;
    std::array<Quat, kMaxSegments> q_earth_segment = skeleton::identity_quats();
    std::array<Vec3, kMaxSegments> sensor_position_m = skeleton::zero_vec3s();
};

class StreamMotion {
public:
    /// The built-in walk on `model` (which must be the default 15-segment body or use its
    /// segment names; segments with other names stay in the T-pose).
    static StreamMotion walk(const skeleton::BodyModel& model, double calibrate_s);
    /// A BVH clip mapped onto `model`; nullopt with *error set if the file cannot be read,
    /// parsed or mapped.
    static std::optional<StreamMotion> from_bvh_file(const std::string& path, const skeleton::BodyModel& model,
                                                     double calibrate_s, std::string* error);

    /// The pose at time t_s (t = 0 is the start of the still period), with the whole body
    /// turned by heading_rad about the vertical and moved by origin_m (per-subject variety).
    void pose(double t_s, double heading_rad, const Vec3& origin_m, BodyPose& out) const;

    /// Orientations and root joint position only (no forward kinematics), same arguments.
    void orientations(double t_s, double heading_rad, const Vec3& origin_m,
                      std::array<Quat, kMaxSegments>& q_earth_segment, Vec3& root_m) const;

    [[nodiscard]] double calibrate_s() const { return calibrate_s_; }
    [[nodiscard]] const skeleton::BodyModel& model() const { return model_; }
    /// BVH source: the clip's mapped orientations at frame f (no blending, no heading),
    /// for tests. Requires a clip source.
    void clip_frame(std::size_t f, std::array<Quat, kMaxSegments>& q_enu_segment, Vec3* root_m) const;
    [[nodiscard]] bool is_clip() const { return clip_.has_value(); }
    [[nodiscard]] double blend_s() const { return blend_s_; }

private:
    StreamMotion(const skeleton::BodyModel& model, double calibrate_s);
    void walk_orientations(double t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const;
    void clip_orientations(double t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const;
    void clip_at(double clip_t_s, std::array<Quat, kMaxSegments>& q, Vec3& root) const;

    skeleton::BodyModel model_;
    double calibrate_s_ = 2.0;
    double blend_s_ = 1.0;
    // walk: segment index per role (-1 when the model lacks it)
    struct WalkSegments {
        int pelvis = -1, trunk = -1, head = -1;
        int upper_arm[2] = {-1, -1}, forearm[2] = {-1, -1}, hand[2] = {-1, -1};
        int thigh[2] = {-1, -1}, calf[2] = {-1, -1}, foot[2] = {-1, -1};
    } walk_;
    // clip
    std::optional<skeleton::BvhClip> clip_;
    skeleton::BvhSegmentMapping mapping_;
    double clip_heading_rad_ = 0.0;  ///< pelvis heading at frame 0
    Vec3 clip_root0_m_ = Vec3::Zero();
    Vec3 clip_loop_shift_m_ = Vec3::Zero();  ///< horizontal root displacement over one loop
};

}  // namespace mocap::sim
