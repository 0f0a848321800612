// bvh.hpp — BVH (Biovision Hierarchy) reading and writing, and the mapping from a BVH
// skeleton (the CMU clips) onto a BodyModel.
//
// Reading. parse_bvh() takes the whole text and returns a BvhClip or an error naming the
// line. It is strict and bounded (BvhLimits), because files and live streams are untrusted:
// one ROOT; every JOINT has exactly one OFFSET (3 finite numbers) and one CHANNELS list
// (1..6 distinct names of X/Y/Z position/rotation); an End Site has only an OFFSET; joint
// count, depth, frame count, values and token lengths are capped; `Frames:` must equal the
// number of motion rows and every row must hold exactly channels_per_frame finite numbers
// (one frame per line). Memory used is bounded by the limits and by the text size.
//
// Semantics (same as common importers): a joint's local rotation is the product of its
// rotation channels in the order listed (R = R_c0·R_c1·R_c2, see euler.hpp), angles in
// degrees; a position channel replaces that component of the joint's OFFSET (so the root's
// position channels are its absolute position); global = parent_global · local, position =
// parent_position + parent_global · translation.
//
// Axes. BVH is Y-up. This product is ENU Z-up with x forward for the body (body_model.hpp).
// The mapping is the proper rotation   x_enu = Z_bvh,  y_enu = X_bvh,  z_enu = Y_bvh
// (q_enu_bvh = (0.5, 0.5, 0.5, 0.5), a 120° turn about (1,1,1)). A character that faces
// BVH +Z with its left hand on BVH +X (the CMU convention, and what we write) therefore
// faces ENU +x with its left on +y, and its rest pose gives identity joint orientations:
// q_enu_joint = q_enu_bvh ⊗ q_bvh_joint ⊗ conj(q_enu_bvh).
//
// Writing. The writer emits a BodyModel as HIERARCHY (joint names = segment names, OFFSETs
// in a configurable unit, centimetres by default; the root with 6 channels
// Xposition Yposition Zposition + 3 rotations, every other joint 3 rotations, one rotation
// order for all joints, ZXY by default; an End Site at every leaf from SegmentDef::end_m)
// and one MOTION line per frame from world segment orientations and the root position.
// The rest pose of a written file is the T-pose. A generic writer of a parsed clip exists
// for round trips.
//
// Thread-safety: pure functions on values. Cost: parse O(text); global pose O(joints)
// without allocation; append_bvh_motion_line allocates only if `out` lacks capacity.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/frame.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/euler.hpp"

namespace mocap::skeleton {

enum class BvhChannel : std::uint8_t { kXposition, kYposition, kZposition, kXrotation, kYrotation, kZrotation };

/// "Xposition" ... "Zrotation"; nullopt for anything else (case-sensitive, as written).
std::optional<BvhChannel> parse_bvh_channel(std::string_view name);
std::string_view to_string(BvhChannel c);

struct BvhJoint {
    std::string name;
    int parent = -1;                       ///< index into BvhClip::joints, -1 for the root
    Vec3 offset = Vec3::Zero();            ///< in file units, BVH axes
    std::array<BvhChannel, 6> channels{};  ///< first channel_count are used, in file order
    std::uint8_t channel_count = 0;
    std::size_t first_channel = 0;  ///< index of its first value in a motion row
    bool has_end_site = false;
    Vec3 end_offset = Vec3::Zero();  ///< End Site offset (file units), if any
};

struct BvhClip {
    std::vector<BvhJoint> joints;  ///< parents before children (file order)
    std::size_t channels_per_frame = 0;
    std::size_t frame_count = 0;
    double frame_time_s = 0.0;
    std::vector<double> values;  ///< frame_count rows of channels_per_frame values

    int index_of(std::string_view name) const;  ///< -1 if no such joint; O(n)
    std::span<const double> frame(std::size_t f) const {
        return {values.data() + f * channels_per_frame, channels_per_frame};
    }
};

struct BvhLimits {
    std::size_t max_joints = 256;
    std::size_t max_depth = 64;
    std::size_t max_frames = 1'000'000;
    std::size_t max_values = 32'000'000;  ///< frames × channels (256 MB of doubles)
    std::size_t max_token_chars = 128;    ///< longest name or number
};

struct BvhParseResult {
    std::optional<BvhClip> clip;
    std::string error;  ///< "line N: ..." when clip is empty
    explicit operator bool() const { return clip.has_value(); }
};

/// Parses a complete BVH file (HIERARCHY + MOTION).
BvhParseResult parse_bvh(std::string_view text, const BvhLimits& limits = {});

/// Parses only the HIERARCHY block (for a live stream whose frame count is open): the
/// returned clip has no frames; *consumed (if given) is the offset just past the root's
/// closing brace.
BvhParseResult parse_bvh_hierarchy(std::string_view text, const BvhLimits& limits = {},
                                   std::size_t* consumed = nullptr);

/// Parses one MOTION row of exactly out.size() finite numbers (whitespace separated).
/// Returns an empty string on success, else what is wrong.
std::string parse_bvh_motion_line(std::string_view line, std::span<double> out);

/// q_enu_bvh (see the file comment) and the vector mapping both ways.
Quat q_enu_bvh();
inline Vec3 enu_from_bvh(const Vec3& v) {
    return {v.z(), v.x(), v.y()};
}
inline Vec3 bvh_from_enu(const Vec3& v) {
    return {v.y(), v.z(), v.x()};
}

/// Every joint's orientation q_enu_joint and position (metres, ENU) for one frame row.
/// unit_m = metres per file unit (1 for the CMU clips, 0.01 for centimetre files).
/// Spans must hold clip.joints.size() entries (checked by assert). No allocation.
void bvh_global_pose(const BvhClip& clip, std::span<const double> frame_values, double unit_m,
                     std::span<Quat> q_enu_joint, std::span<Vec3> p_enu_joint_m);

/// Writes a parsed clip back as BVH text (6 decimals). parse_bvh(write_bvh(c)) == c to
/// within 5e-7 in every value.
std::string write_bvh(const BvhClip& clip);

// --- BodyModel writer ------------------------------------------------------------------

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

// --- Mapping a BVH skeleton onto a BodyModel --------------------------------------------

/// Where one model segment comes from: the first of `joints` present in the clip drives
/// the segment (its global orientation and position); the first of `tips` present gives
/// the segment's long axis in the BVH rest pose ("End Site" = that joint's End Site;
/// empty list = no long-axis correction, as for the pelvis).
struct BvhSegmentSource {
    std::string segment;
    std::vector<std::string> joints;
    std::vector<std::string> tips;
};

/// The 15 default segments from the CMU skeleton as converted for 3ds Max (the clips in
/// the shared motion data: Hips, lowerback, Chest, Chest2, Neck, Head, LeftShoulder,
/// LeftElbow, lhand, LeftHip, LeftKnee, LeftAnkle, LeftToe, ...), with the names of the
/// other common CMU conversion (Hips, Spine1, Head, LeftArm, LeftForeArm, LeftHand,
/// LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, ...) as fallbacks:
///   pelvis <- Hips;  trunk <- Chest2 (the joint the arms hang from, tip Neck);
///   head <- Head;  upper arm <- LeftArm|LeftShoulder (LeftArm first: in the second naming
///   LeftShoulder is the collar);  forearm <- LeftElbow|LeftForeArm;
///   hand <- lhand|LeftHand;  thigh <- LeftHip|LeftUpLeg;  calf <- LeftKnee|LeftLeg;
///   foot <- LeftAnkle|LeftFoot;  and the same on the right.
std::vector<BvhSegmentSource> cmu_segment_sources();

/// Per model segment: the driving BVH joint and the constant rotation q_joint_segment with
/// q_enu_segment = q_enu_joint ⊗ q_joint_segment. It turns the model's T-pose long axis
/// (SegmentDef::end_m) onto the joint's rest-pose bone direction (shortest arc), so that
/// segment orientations follow the model's frame convention (identity = T-pose). The CMU
/// rest pose has the arms down, so a CMU clip at rest yields the N-pose (calibration.hpp).
struct BvhSegmentMapping {
    std::size_t segment_count = 0;
    std::array<int, kMaxSegments> joint{};
    std::array<Quat, kMaxSegments> q_joint_segment = identity_quats();
    std::array<Vec3, kMaxSegments> rest_tip_enu = zero_vec3s();  ///< joint -> tip at rest, file units
};

struct BvhMappingResult {
    std::optional<BvhSegmentMapping> mapping;
    std::string error;  ///< names the segment or joint that could not be resolved
    explicit operator bool() const { return mapping.has_value(); }
};

/// Every model segment must have a source whose joint exists in the clip.
BvhMappingResult map_bvh_to_model(const BvhClip& clip, const BodyModel& model,
                                  std::span<const BvhSegmentSource> sources);

/// The model `base` (names, hierarchy, node ids, filters) with the clip's dimensions: each
/// segment's offset is its driving joint's rest position relative to the parent's driving
/// joint, turned into the parent's T-pose frame (conj(q_joint_segment) of the parent); each
/// end_m keeps the base direction with the clip's rest bone length (segments without a
/// tip keep base.end_m); root_height_m is the root joint's rest height above the lowest
/// rest point of the clip. Forward kinematics of the result with bvh_segment_pose()
/// orientations then reproduces the clip's limb joint positions (see the tests).
/// unit_m = metres per file unit. No validation beyond the mapping's.
BodyModel body_model_from_bvh(const BvhClip& clip, const BvhSegmentMapping& mapping, const BodyModel& base,
                              double unit_m);

/// Segment orientations (ENU) and segment origins (the driving joint's position, metres)
/// from one frame's global joint pose (bvh_global_pose). No allocation.
void bvh_segment_pose(const BvhSegmentMapping& mapping, std::span<const Quat> q_enu_joint,
                      std::span<const Vec3> p_enu_joint_m, std::span<Quat> q_enu_segment,
                      std::span<Vec3> p_enu_segment_m);

}  // namespace mocap::skeleton
