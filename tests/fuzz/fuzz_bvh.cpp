// Fuzz target: the BVH reader (server/skeleton parse_bvh, parse_bvh_hierarchy), the one
// mocap-sim reads motion files with.
//
// Memory must stay bounded by the text size and BvhLimits (the fuzzer runs with a malloc
// limit, see run_fuzzers.sh). An accepted clip must be consistent (parents before
// children, channel indices inside a row, values = frames x channels, all finite), every
// frame's global pose must be computable, and write_bvh() must give text that parses back
// to the same shape (the round trip bvh.hpp promises).
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include "fuzz_target.hpp"
#include "skeleton/bvh_write.hpp"

namespace sk = mocap::skeleton;

MOCAP_FUZZ_ENTRY(bvh) {
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    std::size_t consumed = 0;
    const sk::BvhParseResult h = sk::parse_bvh_hierarchy(text, {}, &consumed);
    if (h)
        MOCAP_FUZZ_CHECK(consumed <= size, "hierarchy consumed past the text");
    else
        MOCAP_FUZZ_CHECK(!h.error.empty(), "hierarchy rejected without an error");

    const sk::BvhParseResult r = sk::parse_bvh(text);
    if (!r) {
        MOCAP_FUZZ_CHECK(r.error.rfind("line ", 0) == 0, r.error.c_str());
        return 0;
    }
    const sk::BvhClip& clip = *r.clip;
    MOCAP_FUZZ_CHECK(!clip.joints.empty() && clip.joints[0].parent == -1, "root");
    std::size_t channels = 0;
    for (std::size_t j = 0; j < clip.joints.size(); ++j) {
        const sk::BvhJoint& joint = clip.joints[j];
        MOCAP_FUZZ_CHECK(j == 0 || (joint.parent >= 0 && static_cast<std::size_t>(joint.parent) < j),
                         "parent after child");
        MOCAP_FUZZ_CHECK(joint.channel_count <= 6, "channel count");
        MOCAP_FUZZ_CHECK(joint.first_channel == channels, "first_channel");
        channels += joint.channel_count;
        MOCAP_FUZZ_CHECK(joint.offset.allFinite(), "offset not finite");
    }
    MOCAP_FUZZ_CHECK(channels == clip.channels_per_frame, "channels_per_frame");
    MOCAP_FUZZ_CHECK(clip.values.size() == clip.frame_count * clip.channels_per_frame, "values != frames x channels");
    for (double v : clip.values)
        MOCAP_FUZZ_CHECK(std::isfinite(v), "motion value not finite");

    std::vector<sk::Quat> q(clip.joints.size());
    std::vector<sk::Vec3> p(clip.joints.size());
    for (std::size_t f = 0; f < clip.frame_count && f < 4; ++f) {
        sk::bvh_global_pose(clip, clip.frame(f), 1.0, q, p);
        for (const sk::Quat& qj : q) {
            MOCAP_FUZZ_CHECK(std::fabs(qj.norm() - 1.0) < 1e-6, "joint orientation not unit");
        }
    }

    const sk::BvhParseResult back = sk::parse_bvh(sk::write_bvh(clip));
    MOCAP_FUZZ_CHECK(back, back.error.c_str());
    MOCAP_FUZZ_CHECK(back.clip->joints.size() == clip.joints.size() && back.clip->frame_count == clip.frame_count &&
                         back.clip->channels_per_frame == clip.channels_per_frame,
                     "round trip changed the clip's shape");
    return 0;
}
