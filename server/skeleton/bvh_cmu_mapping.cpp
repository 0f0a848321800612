// bvh_cmu_mapping.cpp — mapping a BVH skeleton (the CMU clips) onto a BodyModel
// (bvh_mapping.hpp).
#include "skeleton/bvh_mapping.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace mocap::skeleton {

std::vector<BvhSegmentSource> cmu_segment_sources() {
    std::vector<BvhSegmentSource> s;
    auto add = [&](std::string_view seg, std::vector<std::string> joints, std::vector<std::string> tips) {
        s.push_back(BvhSegmentSource{std::string(seg), std::move(joints), std::move(tips)});
    };
    add(seg::kPelvis, {"Hips"}, {});
    add(seg::kTrunk, {"Chest2", "Spine1"}, {"Neck", "Neck1"});
    add(seg::kHead, {"Head"}, {"End Site"});
    for (const bool left : {true, false}) {
        const std::string l = left ? "Left" : "Right";
        const std::string c = left ? "L" : "R";
        const std::string lc = left ? "l" : "r";
        // "LeftArm" first: in the second naming "LeftShoulder" is the collar.
        add(left ? seg::kLeftUpperArm : seg::kRightUpperArm, {l + "Arm", l + "Shoulder"}, {l + "Elbow", l + "ForeArm"});
        add(left ? seg::kLeftForearm : seg::kRightForearm, {l + "Elbow", l + "ForeArm"}, {l + "Wrist", l + "Hand"});
        add(left ? seg::kLeftHand : seg::kRightHand, {lc + "hand", l + "Hand"},
            {c + "Fingers", l + "HandIndex1", l + "FingerBase", "End Site"});
        add(left ? seg::kLeftThigh : seg::kRightThigh, {l + "Hip", l + "UpLeg"}, {l + "Knee", l + "Leg"});
        add(left ? seg::kLeftCalf : seg::kRightCalf, {l + "Knee", l + "Leg"}, {l + "Ankle", l + "Foot"});
        add(left ? seg::kLeftFoot : seg::kRightFoot, {l + "Ankle", l + "Foot"}, {l + "Toe", l + "ToeBase", "End Site"});
    }
    return s;
}

namespace {

/// Rest-pose direction from joint `j` to the first resolvable tip: "End Site" (the
/// joint's own End Site) or a descendant joint (the sum of the offsets on the way down).
bool resolve_tip(const BvhClip& clip, int j, const std::vector<std::string>& tips, Vec3& dir) {
    for (const std::string& tip : tips) {
        if (tip == "End Site") {
            const BvhJoint& joint = clip.joints[static_cast<std::size_t>(j)];
            if (!joint.has_end_site) continue;
            dir = joint.end_offset;
            return true;
        }
        int k = clip.index_of(tip);
        if (k == j) continue;
        Vec3 d = Vec3::Zero();
        while (k >= 0 && k != j) {
            d += clip.joints[static_cast<std::size_t>(k)].offset;
            k = clip.joints[static_cast<std::size_t>(k)].parent;
        }
        if (k == j) {
            dir = d;
            return true;
        }
    }
    return false;
}

}  // namespace

BvhMappingResult map_bvh_to_model(const BvhClip& clip, const BodyModel& model,
                                  std::span<const BvhSegmentSource> sources) {
    BvhMappingResult r;
    if (model.size() > kMaxSegments) {
        r.error = "model has more than " + std::to_string(kMaxSegments) + " segments";
        return r;
    }
    BvhSegmentMapping m;
    m.segment_count = model.size();
    for (std::size_t i = 0; i < model.size(); ++i) {
        const SegmentDef& s = model.segments[i];
        const auto src = std::find_if(sources.begin(), sources.end(),
                                      [&](const BvhSegmentSource& e) { return e.segment == s.name; });
        if (src == sources.end()) {
            r.error = "no BVH source listed for segment '" + s.name + "'";
            return r;
        }
        // The first listed joint present in the file whose tip resolves (any present one
        // when no tips are listed) drives the segment.
        int joint = -1;
        Vec3 rest_dir = Vec3::Zero();
        bool any_present = false;
        for (const std::string& cand : src->joints) {
            const int jc = clip.index_of(cand);
            if (jc < 0) continue;
            any_present = true;
            if (src->tips.empty() || resolve_tip(clip, jc, src->tips, rest_dir)) {
                joint = jc;
                break;
            }
        }
        if (joint < 0) {
            r.error = "segment '" + s.name + "': " +
                      (any_present ? std::string("no tip joint found below its BVH joint for the long axis")
                                   : std::string("none of its BVH joints is in the file"));
            return r;
        }
        const Vec3 d_rest = enu_from_bvh(rest_dir);
        Quat q_c = Quat::Identity();
        if (d_rest.norm() > 1e-9 && s.end_m.norm() > 1e-9) q_c = Quat::FromTwoVectors(s.end_m, d_rest).normalized();
        m.joint[i] = joint;
        m.q_joint_segment[i] = q_c;
        m.rest_tip_enu[i] = d_rest;
    }
    r.mapping = m;
    return r;
}

BodyModel body_model_from_bvh(const BvhClip& clip, const BvhSegmentMapping& mapping, const BodyModel& base,
                              double unit_m) {
    BodyModel out = base;
    const std::size_t n = std::min(base.size(), mapping.segment_count);
    if (n == 0) return out;
    // Rest pose: all channels zero.
    std::vector<double> zeros(clip.channels_per_frame, 0.0);
    std::vector<Quat> q(clip.joints.size());
    std::vector<Vec3> p(clip.joints.size());
    bvh_global_pose(clip, zeros, unit_m, q, p);
    double lowest = 0.0;
    bool first = true;
    for (std::size_t j = 0; j < clip.joints.size(); ++j) {
        const double z = clip.joints[j].has_end_site
                             ? std::min(p[j].z(), p[j].z() + enu_from_bvh(clip.joints[j].end_offset).z() * unit_m)
                             : p[j].z();
        if (first || z < lowest) lowest = z;
        first = false;
    }
    for (std::size_t i = 0; i < n; ++i) {
        SegmentDef& s = out.segments[i];
        const Vec3 here = p[static_cast<std::size_t>(mapping.joint[i])];
        if (s.parent >= 0) {
            const auto par = static_cast<std::size_t>(s.parent);
            s.offset_m = mapping.q_joint_segment[par].conjugate()._transformVector(
                here - p[static_cast<std::size_t>(mapping.joint[par])]);
        } else {
            s.offset_m = Vec3::Zero();
            out.root_height_m = here.z() - lowest;
        }
        const double len = mapping.rest_tip_enu[i].norm() * unit_m;
        if (len > 1e-9 && s.end_m.norm() > 1e-9) s.end_m = s.end_m.normalized() * len;
    }
    return out;
}

void bvh_segment_pose(const BvhSegmentMapping& mapping, std::span<const Quat> q_enu_joint,
                      std::span<const Vec3> p_enu_joint_m, std::span<Quat> q_enu_segment,
                      std::span<Vec3> p_enu_segment_m) {
    assert(q_enu_segment.size() >= mapping.segment_count && p_enu_segment_m.size() >= mapping.segment_count);
    for (std::size_t i = 0; i < mapping.segment_count; ++i) {
        const auto j = static_cast<std::size_t>(mapping.joint[i]);
        q_enu_segment[i] = q_enu_joint[j] * mapping.q_joint_segment[i];
        p_enu_segment_m[i] = p_enu_joint_m[j];
    }
}

}  // namespace mocap::skeleton
