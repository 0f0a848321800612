#include "skeleton/bvh.hpp"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <numbers>

#include "core/parse_number.hpp"

namespace mocap::skeleton {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

bool is_space(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

/// Whitespace tokenizer that keeps line numbers; braces are tokens of their own even when
/// glued to a name ("Hips{").
class Lexer {
public:
    Lexer(std::string_view text, std::size_t max_token) : s_(text), max_token_(max_token) {}

    /// Next token, empty at the end of the text; sets error() for an over-long token.
    std::string_view next() {
        while (pos_ < s_.size() && is_space(s_[pos_])) {
            if (s_[pos_] == '\n') ++line_;
            ++pos_;
        }
        tok_line_ = line_;
        if (pos_ >= s_.size()) return {};
        const std::size_t start = pos_;
        if (s_[pos_] == '{' || s_[pos_] == '}') {
            ++pos_;
            return s_.substr(start, 1);
        }
        while (pos_ < s_.size() && !is_space(s_[pos_]) && s_[pos_] != '{' && s_[pos_] != '}')
            ++pos_;
        if (pos_ - start > max_token_) {
            too_long_ = true;
            return {};
        }
        return s_.substr(start, pos_ - start);
    }

    bool too_long() const { return too_long_; }
    std::size_t line() const { return tok_line_; }
    std::size_t pos() const { return pos_; }
    std::string_view text() const { return s_; }

    /// Moves past the end of the current line (the rest of it must be blank).
    bool finish_line() {
        while (pos_ < s_.size() && s_[pos_] != '\n') {
            if (!is_space(s_[pos_])) return false;
            ++pos_;
        }
        if (pos_ < s_.size()) {
            ++pos_;
            ++line_;
        }
        return true;
    }

private:
    std::string_view s_;
    std::size_t max_token_;
    std::size_t pos_ = 0;
    std::size_t line_ = 1;
    std::size_t tok_line_ = 1;
    bool too_long_ = false;
};

bool valid_joint_name(std::string_view t) {
    return !t.empty() && t != "{" && t != "}";
}

std::string at(const Lexer& lx, const std::string& msg) {
    return "line " + std::to_string(lx.line()) + ": " + msg;
}

std::string quoted(std::string_view t) {
    std::string q;  // built by append: g++ 12 warns falsely (-Wrestrict) on "'" + std::string
    q.reserve(t.size() + 2);
    q.push_back('\'');
    q.append(t);
    q.push_back('\'');
    return q;
}

struct OpenBlock {
    int joint = 0;
    bool end_site = false;
    bool offset_seen = false;
    bool channels_seen = false;
};

/// Reads one token that must be `want`.
bool expect(Lexer& lx, std::string_view want, std::string& err) {
    const std::string_view t = lx.next();
    if (lx.too_long()) {
        err = at(lx, "token too long");
        return false;
    }
    if (t != want) {
        err = at(lx, "expected " + quoted(want) + ", found " + (t.empty() ? std::string("end of file") : quoted(t)));
        return false;
    }
    return true;
}

std::string parse_hierarchy_block(Lexer& lx, const BvhLimits& limits, BvhClip& clip) {
    std::string err;
    if (!expect(lx, "HIERARCHY", err)) return err;
    if (!expect(lx, "ROOT", err)) return err;
    std::string_view name = lx.next();
    if (lx.too_long()) return at(lx, "token too long");
    if (!valid_joint_name(name)) return at(lx, "ROOT needs a name");
    clip.joints.push_back(BvhJoint{});
    clip.joints.back().name = std::string(name);
    if (!expect(lx, "{", err)) return err;
    std::vector<OpenBlock> stack;
    stack.reserve(std::min<std::size_t>(limits.max_depth, 64) + 1);
    stack.push_back(OpenBlock{0, false, false, false});

    while (!stack.empty()) {
        const std::string_view t = lx.next();
        if (lx.too_long()) return at(lx, "token too long");
        OpenBlock& top = stack.back();
        BvhJoint& joint = clip.joints[static_cast<std::size_t>(top.joint)];
        if (t.empty()) return at(lx, "unexpected end of file inside joint " + quoted(joint.name));
        if (t == "OFFSET") {
            if (top.offset_seen) return at(lx, "second OFFSET in joint " + quoted(joint.name));
            Vec3 v;
            for (int k = 0; k < 3; ++k) {
                const std::string_view n = lx.next();
                if (lx.too_long()) return at(lx, "token too long");
                if (!core::parse_number(n, v[k])) return at(lx, "OFFSET needs 3 finite numbers, found " + quoted(n));
            }
            (top.end_site ? joint.end_offset : joint.offset) = v;
            top.offset_seen = true;
        } else if (t == "CHANNELS") {
            if (top.end_site) return at(lx, "CHANNELS inside an End Site");
            if (top.channels_seen) return at(lx, "second CHANNELS in joint " + quoted(joint.name));
            std::size_t n = 0;
            const std::string_view ns = lx.next();
            if (lx.too_long()) return at(lx, "token too long");
            if (!core::parse_number(ns, n) || n > 6) return at(lx, "CHANNELS count must be 0..6, found " + quoted(ns));
            bool used[6] = {false, false, false, false, false, false};
            for (std::size_t k = 0; k < n; ++k) {
                const std::string_view cs = lx.next();
                if (lx.too_long()) return at(lx, "token too long");
                const auto c = parse_bvh_channel(cs);
                if (!c) return at(lx, "unknown channel " + (cs.empty() ? std::string("(end of file)") : quoted(cs)));
                const auto ci = static_cast<std::size_t>(*c);
                if (used[ci]) return at(lx, "channel " + quoted(cs) + " listed twice");
                used[ci] = true;
                joint.channels[k] = *c;
            }
            joint.channel_count = static_cast<std::uint8_t>(n);
            joint.first_channel = clip.channels_per_frame;
            clip.channels_per_frame += n;
            top.channels_seen = true;
        } else if (t == "JOINT" || t == "End") {
            const bool end_site = t == "End";
            if (top.end_site) return at(lx, "an End Site cannot have children");
            if (!top.offset_seen || !top.channels_seen) {
                return at(lx, "joint " + quoted(joint.name) + " needs OFFSET and CHANNELS before its children");
            }
            if (stack.size() >= limits.max_depth) {
                return at(lx, "hierarchy deeper than " + std::to_string(limits.max_depth));
            }
            const int parent = top.joint;
            if (end_site) {
                if (!expect(lx, "Site", err)) return err;
                if (joint.has_end_site) return at(lx, "second End Site in joint " + quoted(joint.name));
                joint.has_end_site = true;
                if (!expect(lx, "{", err)) return err;
                stack.push_back(OpenBlock{parent, true, false, false});
            } else {
                const std::string_view jn = lx.next();
                if (lx.too_long()) return at(lx, "token too long");
                if (!valid_joint_name(jn)) return at(lx, "JOINT needs a name");
                if (clip.joints.size() >= limits.max_joints) {
                    return at(lx, "more than " + std::to_string(limits.max_joints) + " joints");
                }
                if (clip.index_of(jn) >= 0) return at(lx, "duplicate joint name " + quoted(jn));
                BvhJoint j;
                j.name = std::string(jn);
                j.parent = parent;
                clip.joints.push_back(std::move(j));
                if (!expect(lx, "{", err)) return err;
                stack.push_back(OpenBlock{static_cast<int>(clip.joints.size()) - 1, false, false, false});
            }
        } else if (t == "}") {
            if (!top.offset_seen) {
                return at(lx, (top.end_site ? std::string("End Site of ") : std::string("joint ")) +
                                  quoted(joint.name) + " has no OFFSET");
            }
            if (!top.end_site && !top.channels_seen) return at(lx, "joint " + quoted(joint.name) + " has no CHANNELS");
            stack.pop_back();
        } else {
            return at(lx, "unexpected " + quoted(t) + " in joint " + quoted(joint.name));
        }
    }
    return {};
}

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

std::optional<BvhChannel> parse_bvh_channel(std::string_view name) {
    static constexpr std::array<std::string_view, 6> kNames{"Xposition", "Yposition", "Zposition",
                                                            "Xrotation", "Yrotation", "Zrotation"};
    for (std::size_t i = 0; i < kNames.size(); ++i) {
        if (name == kNames[i]) return static_cast<BvhChannel>(i);
    }
    return std::nullopt;
}

std::string_view to_string(BvhChannel c) {
    static constexpr std::array<std::string_view, 6> kNames{"Xposition", "Yposition", "Zposition",
                                                            "Xrotation", "Yrotation", "Zrotation"};
    return kNames[static_cast<std::size_t>(c)];
}

int BvhClip::index_of(std::string_view name) const {
    for (std::size_t i = 0; i < joints.size(); ++i) {
        if (joints[i].name == name) return static_cast<int>(i);
    }
    return -1;
}

BvhParseResult parse_bvh_hierarchy(std::string_view text, const BvhLimits& limits, std::size_t* consumed) {
    BvhParseResult r;
    Lexer lx(text, limits.max_token_chars);
    BvhClip clip;
    r.error = parse_hierarchy_block(lx, limits, clip);
    if (!r.error.empty()) return r;
    if (consumed) *consumed = lx.pos();
    r.clip = std::move(clip);
    return r;
}

std::string parse_bvh_motion_line(std::string_view line, std::span<double> out) {
    std::size_t count = 0;
    std::size_t i = 0;
    while (true) {
        while (i < line.size() && is_space(line[i]))
            ++i;
        if (i >= line.size()) break;
        const std::size_t start = i;
        while (i < line.size() && !is_space(line[i]))
            ++i;
        const std::string_view tok = line.substr(start, i - start);
        if (count >= out.size()) {
            return "too many values: expected " + std::to_string(out.size());
        }
        if (!core::parse_number(tok, out[count])) return "not a finite number: " + quoted(tok.substr(0, 32));
        ++count;
    }
    if (count != out.size()) {
        return "expected " + std::to_string(out.size()) + " values, found " + std::to_string(count);
    }
    return {};
}

BvhParseResult parse_bvh(std::string_view text, const BvhLimits& limits) {
    BvhParseResult r;
    Lexer lx(text, limits.max_token_chars);
    BvhClip clip;
    r.error = parse_hierarchy_block(lx, limits, clip);
    if (!r.error.empty()) return r;

    std::string_view t = lx.next();
    if (lx.too_long()) return r.error = at(lx, "token too long"), r;
    if (t == "ROOT") return r.error = at(lx, "only one ROOT is supported"), r;
    if (t != "MOTION") {
        r.error = at(lx, "expected 'MOTION', found " + (t.empty() ? std::string("end of file") : quoted(t)));
        return r;
    }
    if (!expect(lx, "Frames:", r.error)) return r;
    std::size_t frames = 0;
    t = lx.next();
    if (!core::parse_number(t, frames)) return r.error = at(lx, "Frames: needs a non-negative integer"), r;
    if (frames > limits.max_frames) {
        return r.error = at(lx, "more than " + std::to_string(limits.max_frames) + " frames"), r;
    }
    if (clip.channels_per_frame > 0 && frames > limits.max_values / clip.channels_per_frame) {
        return r.error = at(lx, "frames x channels exceeds " + std::to_string(limits.max_values) + " values"), r;
    }
    if (!expect(lx, "Frame", r.error) || !expect(lx, "Time:", r.error)) return r;
    t = lx.next();
    double ft = 0.0;
    if (!core::parse_number(t, ft) || ft <= 0.0) return r.error = at(lx, "Frame Time: needs a positive number"), r;
    if (!lx.finish_line()) return r.error = at(lx, "unexpected text after Frame Time"), r;

    clip.frame_count = frames;
    clip.frame_time_s = ft;
    const std::size_t total = frames * clip.channels_per_frame;
    // Reserve from the declared size only as far as the text could possibly hold
    // (every value takes at least two characters), so a lying header cannot allocate.
    clip.values.reserve(std::min(total, text.size() / 2 + 1));

    std::size_t pos = lx.pos();
    std::size_t line_no = lx.line() + 1;
    std::size_t rows = 0;
    std::vector<double> row(clip.channels_per_frame);
    while (pos < text.size()) {
        std::size_t eol = text.find('\n', pos);
        if (eol == std::string_view::npos) eol = text.size();
        const std::string_view line = text.substr(pos, eol - pos);
        const bool blank = std::all_of(line.begin(), line.end(), is_space);
        if (!blank) {
            if (rows >= frames) {
                r.error =
                    "line " + std::to_string(line_no) + ": more motion rows than Frames: " + std::to_string(frames);
                return r;
            }
            const std::string e = parse_bvh_motion_line(line, row);
            if (!e.empty()) {
                r.error = "line " + std::to_string(line_no) + ": frame " + std::to_string(rows) + ": " + e;
                return r;
            }
            clip.values.insert(clip.values.end(), row.begin(), row.end());
            ++rows;
        }
        pos = eol + 1;
        ++line_no;
    }
    if (rows != frames) {
        r.error = "line " + std::to_string(line_no) + ": Frames: says " + std::to_string(frames) + " but " +
                  std::to_string(rows) + " motion rows follow";
        return r;
    }
    r.clip = std::move(clip);
    return r;
}

Quat q_enu_bvh() {
    return Quat(0.5, 0.5, 0.5, 0.5);
}

void bvh_global_pose(const BvhClip& clip, std::span<const double> frame_values, double unit_m,
                     std::span<Quat> q_enu_joint, std::span<Vec3> p_enu_joint_m) {
    const std::size_t n = clip.joints.size();
    assert(q_enu_joint.size() >= n && p_enu_joint_m.size() >= n);
    assert(frame_values.size() >= clip.channels_per_frame);
    // Compose in ENU directly: conjugating by q_enu_bvh commutes with the products.
    const Quat qp = q_enu_bvh();
    const Quat qp_inv = qp.conjugate();
    for (std::size_t j = 0; j < n; ++j) {
        const BvhJoint& joint = clip.joints[j];
        Vec3 t = joint.offset;
        Quat q = Quat::Identity();
        for (std::size_t c = 0; c < joint.channel_count; ++c) {
            const double v = frame_values[joint.first_channel + c];
            const auto ch = joint.channels[c];
            const int ci = static_cast<int>(ch);
            if (ci < 3) {
                t[ci] = v;
            } else {
                q = q * axis_rotation(static_cast<Axis>(ci - 3), v * kDegToRad);
            }
        }
        const Quat q_local = qp * q * qp_inv;
        const Vec3 t_enu = enu_from_bvh(t) * unit_m;
        if (joint.parent < 0) {
            q_enu_joint[j] = q_local.normalized();
            p_enu_joint_m[j] = t_enu;
        } else {
            const auto p = static_cast<std::size_t>(joint.parent);
            q_enu_joint[j] = (q_enu_joint[p] * q_local).normalized();
            p_enu_joint_m[j] = p_enu_joint_m[p] + q_enu_joint[p]._transformVector(t_enu);
        }
    }
}

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
    append_number(out, frame_time_s, 6);
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

// --- Mapping ----------------------------------------------------------------------------

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
