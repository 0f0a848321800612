#include "filter_tool/chain_file.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>

#include <toml++/toml.h>

namespace mocap::tools {
namespace {

bool valid_name(const std::string& n) {
    if (n.empty() || n.size() > 64) return false;
    for (const char c : n) {
        const bool ok =
            (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
        if (!ok) return false;
    }
    return true;
}

/// A 3-vector from a TOML array; nullopt unless three finite numbers, not all zero.
std::optional<math::Vec3> vec3_of(const toml::node* node) {
    const toml::array* a = node ? node->as_array() : nullptr;
    if (a == nullptr || a->size() != 3) return std::nullopt;
    math::Vec3 v;
    for (std::size_t i = 0; i < 3; ++i) {
        const auto x = (*a)[i].value<double>();
        if (!x || !std::isfinite(*x)) return std::nullopt;
        v[static_cast<Eigen::Index>(i)] = *x;
    }
    if (v.norm() < 1e-9) return std::nullopt;
    return v.normalized();
}

std::optional<fusion::JointType> joint_type_of(std::string_view s) {
    if (s == "hinge") return fusion::JointType::kHinge;
    if (s == "2dof") return fusion::JointType::kTwoDof;
    if (s == "ball") return fusion::JointType::kBall;
    return std::nullopt;
}

bool fail(std::string* error, const std::string& text) {
    if (error) *error = text;
    return false;
}

bool parse_joint(const toml::table& t, std::size_t index, const std::vector<ChainSegment>& segments, ChainJoint& out,
                 std::string* error) {
    const std::string where = "joint " + std::to_string(index + 1) + ": ";
    for (const auto& [key, node] : t) {
        static const std::set<std::string_view> kKnown = {"parent",     "child",          "type", "axis_parent",
                                                          "axis_child", "axis_angle_deg", "axis"};
        if (!kKnown.contains(key.str())) return fail(error, where + "unknown key '" + std::string(key.str()) + "'");
    }
    const auto find = [&](const char* key, std::string& name, int& index_out) {
        name = t[key].value_or(std::string());
        for (std::size_t i = 0; i < segments.size(); ++i) {
            if (segments[i].name == name) {
                index_out = static_cast<int>(i);
                return true;
            }
        }
        return fail(error, where + key + " '" + name + "' is not a segment");
    };
    if (!find("parent", out.parent, out.def.parent) || !find("child", out.child, out.def.child)) return false;
    const auto type = joint_type_of(t["type"].value_or(std::string("hinge")));
    if (!type) return fail(error, where + "type must be hinge, 2dof or ball");
    out.def.type = *type;
    const std::string axis_mode = t["axis"].value_or(std::string());
    if (!axis_mode.empty() && axis_mode != "estimate" && axis_mode != "given") {
        return fail(error, where + "axis must be \"estimate\" or \"given\"");
    }
    const bool has_p = t.contains("axis_parent"), has_c = t.contains("axis_child");
    if (has_p != has_c) return fail(error, where + "give both axis_parent and axis_child, or neither");
    if (has_p && axis_mode != "estimate") {
        const auto p = vec3_of(t.get("axis_parent"));
        const auto c = vec3_of(t.get("axis_child"));
        if (!p || !c) return fail(error, where + "an axis must be three finite numbers, not all zero");
        out.def.axis_parent = *p;
        out.def.axis_child = *c;
        out.def.axes_known = true;
    }
    const double angle_deg = t["axis_angle_deg"].value_or(90.0);
    if (!std::isfinite(angle_deg) || angle_deg < 0.0 || angle_deg > 180.0) {
        return fail(error, where + "axis_angle_deg must be in [0, 180]");
    }
    out.def.cos_axis_angle = std::cos(angle_deg * std::numbers::pi / 180.0);
    return true;
}

}  // namespace

std::optional<ChainRecording> parse_chain_toml(const std::string& toml_path, std::string* error) {
    toml::table root;
    try {
        root = toml::parse_file(toml_path);
    } catch (const toml::parse_error& e) {
        if (error) {
            *error = toml_path + ":" + std::to_string(e.source().begin.line) + ": " + std::string(e.description());
        }
        return std::nullopt;
    }
    const std::filesystem::path folder = std::filesystem::path(toml_path).parent_path();
    ChainRecording chain;
    const auto err = [&](const std::string& text) {
        if (error) *error = toml_path + ": " + text;
        return std::nullopt;
    };
    const toml::array* segs = root["segment"].as_array();
    if (segs == nullptr || segs->empty()) return err("no [[segment]]");
    if (segs->size() > kMaxSegments) return err("at most " + std::to_string(kMaxSegments) + " segments");
    for (const toml::node& n : *segs) {
        const toml::table* t = n.as_table();
        if (t == nullptr) return err("[[segment]] must be a table");
        ChainSegment s;
        s.name = (*t)["name"].value_or(std::string());
        const std::string csv = (*t)["csv"].value_or(std::string());
        if (!valid_name(s.name)) return err("segment name '" + s.name + "' must be 1-64 characters of [A-Za-z0-9_-]");
        if (csv.empty()) return err("segment '" + s.name + "' has no csv");
        for (const ChainSegment& other : chain.segments) {
            if (other.name == s.name) return err("segment '" + s.name + "' named twice");
        }
        s.csv_path = (folder / csv).string();
        chain.segments.push_back(std::move(s));
    }
    if (const toml::array* joints = root["joint"].as_array()) {
        for (std::size_t i = 0; i < joints->size(); ++i) {
            const toml::table* t = (*joints)[i].as_table();
            if (t == nullptr) return err("[[joint]] must be a table");
            ChainJoint j;
            std::string text;
            if (!parse_joint(*t, i, chain.segments, j, &text)) return err(text);
            chain.joints.push_back(std::move(j));
        }
    }
    std::vector<fusion::JointDef> defs;
    for (const ChainJoint& j : chain.joints)
        defs.push_back(j.def);
    if (const std::string text = fusion::ChainEstimator::check(chain.segments.size(), defs); !text.empty()) {
        return err(text);
    }
    return chain;
}

std::optional<ChainRecording> load_chain(const std::string& toml_path, std::string* error) {
    std::optional<ChainRecording> chain = parse_chain_toml(toml_path, error);
    if (!chain) return std::nullopt;
    for (ChainSegment& s : chain->segments) {
        std::ifstream in(s.csv_path, std::ios::binary);
        if (!in) {
            if (error) *error = "cannot open '" + s.csv_path + "' (segment '" + s.name + "')";
            return std::nullopt;
        }
        if (const auto e = read_recording_csv(in, s.recording)) {
            if (error) *error = s.csv_path + ": " + e->to_string();
            return std::nullopt;
        }
        if (s.recording.rows.empty()) {
            if (error) *error = s.csv_path + ": no samples";
            return std::nullopt;
        }
    }
    // One system recorded the chain: the same instants in every file.
    const Recording& first = chain->segments.front().recording;
    const std::size_t n = first.rows.size();
    const std::int64_t span_us = first.rows.back().sample.t_us - first.rows.front().sample.t_us;
    const std::int64_t tol_us = n > 1 ? span_us / static_cast<std::int64_t>(4 * (n - 1)) : 0;
    for (const ChainSegment& s : chain->segments) {
        if (s.recording.rows.size() != n) {
            if (error) {
                *error = s.csv_path + ": " + std::to_string(s.recording.rows.size()) + " rows, but " +
                         chain->segments.front().csv_path + " has " + std::to_string(n);
            }
            return std::nullopt;
        }
        for (std::size_t i = 0; i < n; ++i) {
            if (std::llabs(s.recording.rows[i].sample.t_us - first.rows[i].sample.t_us) > tol_us) {
                if (error) {
                    *error = s.csv_path + ": row " + std::to_string(i + 2) + " is not at the instant of " +
                             chain->segments.front().csv_path + "'s";
                }
                return std::nullopt;
            }
        }
    }
    return chain;
}

}  // namespace mocap::tools
