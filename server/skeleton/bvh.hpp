// bvh.hpp — BVH (Biovision Hierarchy) clips: reading them, their axes and the global pose
// of a frame. Writing is in bvh_write.hpp, the mapping of a BVH skeleton (the CMU clips)
// onto a BodyModel in bvh_mapping.hpp; both build on the types here.
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
// Thread-safety: pure functions on values. Cost: parse O(text); global pose O(joints)
// without allocation.
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

}  // namespace mocap::skeleton
