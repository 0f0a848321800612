// bvh_write.cpp — BVH writing: a parsed clip back to text (round trips), and a BodyModel
// as HIERARCHY plus one MOTION line per frame (bvh_write.hpp).
#include "skeleton/bvh_write.hpp"

#include <cassert>
#include <charconv>
#include <cmath>
#include <numbers>

namespace mocap::skeleton {

namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

void append_number(std::string& out, double v, int decimals) {
    static constexpr double kPow10[] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9};
    char buf[64];
    const double scaled = decimals >= 0 && decimals <= 9 ? std::round(v * kPow10[decimals]) : 0.0;
    if (decimals < 0 || decimals > 9 || !(std::abs(scaled) < 9e15)) {
        // Out of fixed-point range (|v| above ~1e9 at 6 decimals): the shortest text that
        // reads back to the same double ("-2e+73"), which from_chars, Python's float(),
        // assimp and three.js all accept. Fixed notation would need up to 330 characters,
        // more than a reader's token limit, and did not fit this buffer.
        const auto r = std::to_chars(buf, buf + sizeof buf, v);
        out.append(buf, r.ptr);
        return;
    }
    // Integer formatting of the rounded scaled value: ~10x faster than fixed to_chars,
    // which matters for a MOTION line per frame per subject. Never prints "-0.000".
    auto units = static_cast<long long>(scaled);
    if (units < 0) {
        out.push_back('-');
        units = -units;
    }
    const auto r = std::to_chars(buf, buf + sizeof buf, units);
    const auto digits = static_cast<int>(r.ptr - buf);
    if (digits <= decimals) {
        out.append("0");
        if (decimals > 0) {
            out.push_back('.');
            out.append(static_cast<std::size_t>(decimals - digits), '0');
            out.append(buf, r.ptr);
        }
        return;
    }
    out.append(buf, static_cast<std::size_t>(digits - decimals));
    if (decimals > 0) {
        out.push_back('.');
        out.append(buf + (digits - decimals), r.ptr);
    }
}

void append_indent(std::string& out, std::size_t depth) {
    out.append(depth, '\t');
}

void append_vec(std::string& out, const Vec3& v, int decimals) {
    for (int k = 0; k < 3; ++k) {
        out.push_back(' ');
        append_number(out, v[k], decimals);
    }
}

/// Writes HIERARCHY for joints in pre-order (parents first, as parsed or as a valid
/// model is stored), closing blocks as the parent changes.
template <class Parent, class Name, class Offset, class Channels, class EndSite>
void append_hierarchy(std::string& out, std::size_t n, Parent parent, Name name, Offset offset, Channels channels,
                      EndSite end_site) {
    out += "HIERARCHY\n";
    std::vector<int> open;  // joints whose block is open, innermost last
    auto line = [&](std::size_t depth, std::string_view text) {
        append_indent(out, depth);
        out += text;
    };
    auto close_top = [&]() {
        const auto i = static_cast<std::size_t>(open.back());
        const std::size_t depth = open.size();
        if (const std::optional<Vec3> e = end_site(i)) {
            line(depth, "End Site\n");
            line(depth, "{\n");
            line(depth + 1, "OFFSET");
            append_vec(out, *e, 6);
            out += '\n';
            line(depth, "}\n");
        }
        open.pop_back();
        line(open.size(), "}\n");
    };
    for (std::size_t i = 0; i < n; ++i) {
        const int p = parent(i);
        while (!open.empty() && open.back() != p)
            close_top();
        const std::size_t depth = open.size();
        line(depth, p < 0 ? "ROOT " : "JOINT ");
        out += name(i);
        out += '\n';
        line(depth, "{\n");
        line(depth + 1, "OFFSET");
        append_vec(out, offset(i), 6);
        out += '\n';
        line(depth + 1, "CHANNELS ");
        channels(i, out);
        out += '\n';
        open.push_back(static_cast<int>(i));
    }
    while (!open.empty())
        close_top();
}

}  // namespace

std::string write_bvh(const BvhClip& clip) {
    std::string out;
    out.reserve(256 * clip.joints.size() + clip.values.size() * 11 + 64);
    append_hierarchy(
        out, clip.joints.size(), [&](std::size_t i) { return clip.joints[i].parent; },
        [&](std::size_t i) -> const std::string& { return clip.joints[i].name; },
        [&](std::size_t i) { return clip.joints[i].offset; },
        [&](std::size_t i, std::string& o) {
            const BvhJoint& j = clip.joints[i];
            o += std::to_string(j.channel_count);
            for (std::size_t c = 0; c < j.channel_count; ++c) {
                o += ' ';
                o += to_string(j.channels[c]);
            }
        },
        [&](std::size_t i) {
            const BvhJoint& j = clip.joints[i];
            return j.has_end_site ? std::optional<Vec3>(j.end_offset) : std::nullopt;
        });
    out += bvh_motion_header(clip.frame_count, clip.frame_time_s);
    for (std::size_t f = 0; f < clip.frame_count; ++f) {
        const auto row = clip.frame(f);
        for (std::size_t c = 0; c < row.size(); ++c) {
            if (c) out += ' ';
            append_number(out, row[c], 6);
        }
        out += '\n';
    }
    return out;
}

// --- BodyModel writer ------------------------------------------------------------------

std::string bvh_hierarchy_text(const BodyModel& model, const BvhWriteOptions& options) {
    const std::size_t n = model.size();
    std::vector<bool> has_child(n, false);
    for (const SegmentDef& s : model.segments) {
        if (s.parent >= 0) has_child[static_cast<std::size_t>(s.parent)] = true;
    }
    std::string rot;
    for (const Axis a : options.order.axes) {
        rot += ' ';
        rot += axis_letter(a);
        rot += "rotation";
    }
    std::string out;
    append_hierarchy(
        out, n, [&](std::size_t i) { return model.segments[i].parent; },
        [&](std::size_t i) -> const std::string& { return model.segments[i].name; },
        [&](std::size_t i) {
            Vec3 off = model.segments[i].offset_m;
            if (model.segments[i].parent < 0) off.z() += model.root_height_m;  // rest position of the root
            return Vec3(bvh_from_enu(off) * options.units_per_m);
        },
        [&](std::size_t i, std::string& o) {
            o += model.segments[i].parent < 0 ? "6 Xposition Yposition Zposition" : "3";
            o += rot;
        },
        [&](std::size_t i) {
            return has_child[i] ? std::nullopt
                                : std::optional<Vec3>(bvh_from_enu(model.segments[i].end_m) * options.units_per_m);
        });
    return out;
}

std::string bvh_motion_header(std::size_t frames, double frame_time_s) {
    std::string out = "MOTION\nFrames: " + std::to_string(frames) + "\nFrame Time: ";
    if (frame_time_s > 0.0 && frame_time_s < 5e-7) {
        // Six decimals would write 0, which no reader takes: the shortest text that reads back.
        char buf[32];
        const auto r = std::to_chars(buf, buf + sizeof buf, frame_time_s);
        out.append(buf, r.ptr);
    } else {
        append_number(out, frame_time_s, 6);
    }
    out += '\n';
    return out;
}

std::size_t bvh_values_per_frame(const BodyModel& model) {
    return model.size() == 0 ? 0 : 6 + 3 * (model.size() - 1);
}

void append_bvh_motion_line(const BodyModel& model, const BvhWriteOptions& options,
                            std::span<const Quat> q_world_segment, const Vec3& root_position_m, std::string& out) {
    const std::size_t n = model.size();
    assert(q_world_segment.size() >= n);
    const Quat qp = q_enu_bvh();
    const Quat qp_inv = qp.conjugate();
    const Vec3 root = bvh_from_enu(root_position_m) * options.units_per_m;
    for (int k = 0; k < 3; ++k) {
        if (k) out += ' ';
        append_number(out, root[k], options.decimals);
    }
    for (std::size_t i = 0; i < n; ++i) {
        const int parent = model.segments[i].parent;
        const Quat q_local = parent < 0
                                 ? q_world_segment[i]
                                 : q_world_segment[static_cast<std::size_t>(parent)].conjugate() * q_world_segment[i];
        const auto angles = to_euler(options.order, qp_inv * q_local.normalized() * qp);
        for (const double a : angles) {
            out += ' ';
            append_number(out, a * kRadToDeg, options.decimals);
        }
    }
    out += '\n';
}

}  // namespace mocap::skeleton
