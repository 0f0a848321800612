#include "skeleton/body_model.hpp"

#include <cmath>
#include <set>

namespace mocap::skeleton {

int BodyModel::index_of(std::string_view name) const {
    for (std::size_t i = 0; i < segments.size(); ++i) {
        if (segments[i].name == name) return static_cast<int>(i);
    }
    return -1;
}

BodyModel default_body_model(double height_m, std::string_view default_filter) {
    const double h = height_m;
    // Heights above the floor (Winter ratios), used to derive vertical offsets.
    const double hip_z = 0.530 * h;
    const double lumbar_z = hip_z + 0.100 * h;
    const double shoulder_z = 0.818 * h;
    const double neck_z = 0.870 * h;
    const double shoulder_y = 0.5 * 0.259 * h;
    const double hip_y = 0.5 * 0.191 * h;
    const double upper_arm = 0.186 * h;
    const double forearm = 0.146 * h;
    const double hand = 0.108 * h;
    const double thigh = 0.245 * h;
    const double shank = 0.246 * h;
    const double ankle_z = 0.039 * h;
    const double foot_fwd = 0.75 * 0.152 * h;

    BodyModel m;
    m.root_height_m = hip_z;
    auto add = [&](std::string_view name, int parent, const Vec3& offset, const Vec3& end) {
        SegmentDef s;
        s.name = std::string(name);
        s.parent = parent;
        s.offset_m = offset;
        s.end_m = end;
        s.node_id = static_cast<int>(m.segments.size()) + 1;
        s.filter = std::string(default_filter);
        m.segments.push_back(std::move(s));
        return static_cast<int>(m.segments.size()) - 1;
    };
    const int pelvis = add(seg::kPelvis, -1, Vec3::Zero(), Vec3(0, 0, lumbar_z - hip_z));
    const int trunk = add(seg::kTrunk, pelvis, Vec3(0, 0, lumbar_z - hip_z), Vec3(0, 0, neck_z - lumbar_z));
    add(seg::kHead, trunk, Vec3(0, 0, neck_z - lumbar_z), Vec3(0, 0, h - neck_z));
    for (const double side : {1.0, -1.0}) {  // left (+y) then right (-y)
        const bool left = side > 0;
        const int ua = add(left ? seg::kLeftUpperArm : seg::kRightUpperArm, trunk,
                           Vec3(0, side * shoulder_y, shoulder_z - lumbar_z), Vec3(0, side * upper_arm, 0));
        const int fa = add(left ? seg::kLeftForearm : seg::kRightForearm, ua, Vec3(0, side * upper_arm, 0),
                           Vec3(0, side * forearm, 0));
        add(left ? seg::kLeftHand : seg::kRightHand, fa, Vec3(0, side * forearm, 0), Vec3(0, side * hand, 0));
    }
    for (const double side : {1.0, -1.0}) {
        const bool left = side > 0;
        const int th =
            add(left ? seg::kLeftThigh : seg::kRightThigh, pelvis, Vec3(0, side * hip_y, 0), Vec3(0, 0, -thigh));
        const int ca = add(left ? seg::kLeftCalf : seg::kRightCalf, th, Vec3(0, 0, -thigh), Vec3(0, 0, -shank));
        add(left ? seg::kLeftFoot : seg::kRightFoot, ca, Vec3(0, 0, -shank), Vec3(foot_fwd, 0, -ankle_z));
    }
    return m;
}

namespace {

bool valid_name(const std::string& n) {
    if (n.empty() || n.size() > 64) return false;
    for (const char c : n) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_';
        if (!ok) return false;
    }
    return true;
}

bool valid_offset(const Vec3& v) {
    return v.allFinite() && v.norm() < 5.0;
}

}  // namespace

std::vector<std::string> validate(const BodyModel& model) {
    std::vector<std::string> errors;
    const std::size_t n = model.segments.size();
    if (n == 0) {
        errors.emplace_back("body model has no segments");
        return errors;
    }
    if (n > kMaxSegments) {
        errors.push_back("body model has " + std::to_string(n) + " segments, at most " + std::to_string(kMaxSegments) +
                         " are supported");
    }
    if (!std::isfinite(model.root_height_m)) errors.emplace_back("root height is not finite");
    std::set<std::string> names;
    std::set<int> nodes;
    std::size_t roots = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const SegmentDef& s = model.segments[i];
        const std::string where = "segment " + std::to_string(i) + " '" + s.name + "'";
        if (!valid_name(s.name)) {
            errors.push_back(where + ": name must be 1-64 characters of [A-Za-z0-9_]");
        } else if (!names.insert(s.name).second) {
            errors.push_back(where + ": duplicate segment name");
        }
        if (s.parent == -1) {
            ++roots;
            if (i != 0) errors.push_back(where + ": only segment 0 may be the root (parent -1)");
        } else if (s.parent < -1 || s.parent >= static_cast<int>(n)) {
            errors.push_back(where + ": parent index " + std::to_string(s.parent) + " out of range");
        } else if (s.parent >= static_cast<int>(i)) {
            errors.push_back(where + ": parent " + std::to_string(s.parent) +
                             " must come before its child (parents first; cycles are impossible then)");
        }
        if (s.node_id < -1 || s.node_id > 127) {
            errors.push_back(where + ": node id " + std::to_string(s.node_id) + " outside 0..127 (or -1 for none)");
        } else if (s.node_id >= 0 && !nodes.insert(s.node_id).second) {
            errors.push_back(where + ": node id " + std::to_string(s.node_id) + " used by another segment");
        }
        if (!valid_offset(s.offset_m)) errors.push_back(where + ": offset must be finite and shorter than 5 m");
        if (!valid_offset(s.end_m)) errors.push_back(where + ": end must be finite and shorter than 5 m");
    }
    if (roots != 1) errors.push_back("body model needs exactly one root (parent -1), found " + std::to_string(roots));
    return errors;
}

}  // namespace mocap::skeleton
