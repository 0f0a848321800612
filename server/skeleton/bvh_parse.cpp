// bvh_parse.cpp — BVH reading: a bounded tokenizer, the HIERARCHY parser, MOTION rows,
// and the global pose of one frame (the reading semantics in bvh.hpp).
#include "skeleton/bvh.hpp"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <numbers>

#include "core/parse_number.hpp"
#include "skeleton/euler.hpp"

namespace mocap::skeleton {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

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

}  // namespace mocap::skeleton
