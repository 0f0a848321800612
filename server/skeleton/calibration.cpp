#include "skeleton/calibration.hpp"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <numbers>

#include "core/parse_number.hpp"

namespace mocap::skeleton {

std::string_view to_string(CalibrationPose p) {
    switch (p) {
        case CalibrationPose::kTPose:
            return "t-pose";
        case CalibrationPose::kNPose:
            return "n-pose";
        case CalibrationPose::kCustom:
            return "custom";
    }
    return "t-pose";
}

std::string_view to_string(HeadingMode m) {
    return m == HeadingMode::kKeepEarth ? "earth" : "align";
}

namespace {

Quat rot_z(double a) {
    return Quat(std::cos(0.5 * a), 0.0, 0.0, std::sin(0.5 * a));
}
Quat rot_x(double a) {
    return Quat(std::cos(0.5 * a), std::sin(0.5 * a), 0.0, 0.0);
}

/// True if `i` is `root` or one of its descendants (parents come first in a valid model).
bool in_subtree(const BodyModel& model, int i, int root) {
    while (i >= 0) {
        if (i == root) return true;
        i = model.segments[static_cast<std::size_t>(i)].parent;
    }
    return false;
}

}  // namespace

std::array<Quat, kMaxSegments> pose_orientations(const BodyModel& model, CalibrationPose pose) {
    std::array<Quat, kMaxSegments> q = identity_quats();
    if (pose != CalibrationPose::kNPose) return q;
    const int left = model.index_of(seg::kLeftUpperArm);
    const int right = model.index_of(seg::kRightUpperArm);
    const double half_pi = 0.5 * std::numbers::pi;
    for (std::size_t i = 0; i < std::min(model.size(), kMaxSegments); ++i) {
        if (left >= 0 && in_subtree(model, static_cast<int>(i), left)) q[i] = rot_x(-half_pi);
        if (right >= 0 && in_subtree(model, static_cast<int>(i), right)) q[i] = rot_x(half_pi);
    }
    return q;
}

void CalibrationCollector::reset() {
    for (auto& a : acc_)
        a.reset();
    count_.fill(0);
}

void CalibrationCollector::add(std::size_t segment, const Quat& q_earth_sensor) {
    assert(segment < kMaxSegments);
    acc_[segment].add(q_earth_sensor.normalized(), 1.0);
    ++count_[segment];
}

Quat CalibrationCollector::mean(std::size_t segment) const {
    if (count_[segment] == 0) return Quat::Identity();
    return acc_[segment].mean();
}

double CalibrationCollector::spread_rad(std::size_t segment) const {
    const std::size_t n = count_[segment];
    if (n == 0) return 0.0;
    const math::Vec4 v = math::to_wxyz(mean(segment));
    const double lambda = v.dot(acc_[segment].matrix() * v);
    const double s2 = std::clamp(1.0 - lambda / static_cast<double>(n), 0.0, 1.0);
    return 2.0 * std::asin(std::sqrt(s2));
}

CalibrationResult calibrate(const BodyModel& model, const CalibrationCollector& still,
                            const CalibrationOptions& options) {
    CalibrationResult r;
    if (model.size() > kMaxSegments) {
        r.error = "model has more than " + std::to_string(kMaxSegments) + " segments";
        return r;
    }
    std::array<Quat, kMaxSegments> means = identity_quats();
    std::array<bool, kMaxSegments> has{};
    for (std::size_t i = 0; i < model.size(); ++i) {
        const SegmentDef& s = model.segments[i];
        const std::size_t n = still.samples(i);
        if (s.node_id < 0 && n == 0) continue;
        if (n == 0 && options.allow_missing) continue;
        if (n < options.min_samples) {
            r.error = "segment '" + s.name + "': " + std::to_string(n) + " still samples, need " +
                      std::to_string(options.min_samples);
            return r;
        }
        const double spread = still.spread_rad(i);
        if (spread > options.max_spread_rad) {
            r.error = "segment '" + s.name + "' moved during calibration: spread " +
                      std::to_string(spread * 180.0 / std::numbers::pi) + " deg > " +
                      std::to_string(options.max_spread_rad * 180.0 / std::numbers::pi) + " deg";
            return r;
        }
        means[i] = still.mean(i);
        has[i] = true;
    }
    return calibrate_from_means(model, std::span<const Quat>(means.data(), model.size()),
                                std::span<const bool>(has.data(), model.size()), options);
}

CalibrationResult calibrate_from_means(const BodyModel& model, std::span<const Quat> q_earth_sensor_mean,
                                       std::span<const bool> has_sample, const CalibrationOptions& options) {
    CalibrationResult r;
    const std::size_t n = model.size();
    if (n > kMaxSegments || q_earth_sensor_mean.size() < n || has_sample.size() < n) {
        r.error = "segment count mismatch (model " + std::to_string(n) + ")";
        return r;
    }
    double psi = options.facing_heading_rad;
    if (options.facing_source == FacingSource::kFromSensorAxis) {
        const int f = options.facing_segment;
        if (f < 0 || static_cast<std::size_t>(f) >= n || !has_sample[static_cast<std::size_t>(f)]) {
            r.error = "facing segment " + std::to_string(f) + " has no calibration samples";
            return r;
        }
        const Vec3 fwd = q_earth_sensor_mean[static_cast<std::size_t>(f)]._transformVector(options.facing_sensor_axis);
        if (std::hypot(fwd.x(), fwd.y()) < 0.1 * fwd.norm()) {
            r.error = "facing axis of segment '" + model.segments[static_cast<std::size_t>(f)].name +
                      "' is nearly vertical: heading undefined";
            return r;
        }
        psi = std::atan2(fwd.y(), fwd.x());
    }
    if (!std::isfinite(psi)) {
        r.error = "facing heading is not finite";
        return r;
    }
    const std::array<Quat, kMaxSegments> pose =
        options.pose == CalibrationPose::kCustom ? options.custom_pose : pose_orientations(model, options.pose);
    Calibration c;
    c.segment_count = n;
    c.pose = options.pose;
    c.heading_mode = options.heading_mode;
    c.facing_heading_rad = psi;
    const Quat q_heading = rot_z(psi);
    c.q_world_earth = options.heading_mode == HeadingMode::kAlignToForward ? q_heading.conjugate() : Quat::Identity();
    for (std::size_t i = 0; i < n; ++i) {
        if (!has_sample[i]) continue;
        const Quat expected = q_heading * pose[i].normalized();
        c.q_sensor_segment[i] =
            math::canonical((q_earth_sensor_mean[i].normalized().conjugate() * expected).normalized());
        c.calibrated[i] = true;
    }
    r.calibration = c;
    return r;
}

void apply_calibration(const BodyModel& model, const Calibration& cal, std::span<const Quat> q_earth_sensor,
                       std::span<Quat> q_world_segment) {
    const std::size_t n = std::min(model.size(), cal.segment_count);
    assert(q_earth_sensor.size() >= n && q_world_segment.size() >= n);
    for (std::size_t i = 0; i < n; ++i) {
        if (cal.calibrated[i]) {
            q_world_segment[i] = (cal.q_world_earth * q_earth_sensor[i] * cal.q_sensor_segment[i]).normalized();
        } else {
            const int p = model.segments[i].parent;
            q_world_segment[i] = p < 0 ? Quat::Identity() : q_world_segment[static_cast<std::size_t>(p)];
        }
    }
}

// --- text form ---------------------------------------------------------------------------

namespace {

void append_double(std::string& out, double v) {
    char buf[40];
    const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17);
    out.append(buf, r.ptr);
}

void append_quat(std::string& out, const Quat& q) {
    out += '[';
    const double c[4] = {q.w(), q.x(), q.y(), q.z()};
    for (int k = 0; k < 4; ++k) {
        if (k) out += ", ";
        append_double(out, c[k]);
    }
    out += "]\n";
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
        s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
        s.remove_suffix(1);
    return s;
}

bool parse_number(std::string_view t, double& v) {
    return core::parse_number(trim(t), v);
}

bool parse_string(std::string_view t, std::string_view& out) {
    t = trim(t);
    if (t.size() < 2 || t.front() != '"' || t.back() != '"') return false;
    out = t.substr(1, t.size() - 2);
    return out.find('"') == std::string_view::npos && out.find('\\') == std::string_view::npos;
}

/// "[w, x, y, z]" with |q| = 1 ± 1e-6; returns an empty string or the problem.
std::string parse_quat(std::string_view t, Quat& q) {
    t = trim(t);
    if (t.size() < 2 || t.front() != '[' || t.back() != ']') return "expected [w, x, y, z]";
    t = t.substr(1, t.size() - 2);
    double c[4];
    for (int k = 0; k < 4; ++k) {
        const std::size_t comma = t.find(',');
        const bool last = k == 3;
        if (last != (comma == std::string_view::npos)) return "expected 4 numbers in [w, x, y, z]";
        const std::string_view item = last ? t : t.substr(0, comma);
        if (!parse_number(item, c[k])) return "not a finite number: '" + std::string(trim(item).substr(0, 32)) + "'";
        if (!last) t.remove_prefix(comma + 1);
    }
    q = Quat(c[0], c[1], c[2], c[3]);
    const double norm = q.norm();
    if (std::abs(norm - 1.0) > 1e-6) return "quaternion norm is not 1";
    if (std::abs(norm - 1.0) > 1e-14) q.normalize();  // keep saved values bit-exact
    return {};
}

}  // namespace

std::string serialize_calibration(const BodyModel& model, const Calibration& cal) {
    std::string out = "# mocapd sensor-to-segment calibration: q_earth_segment = q_earth_sensor * q_sensor_segment\n";
    out += "format = \"mocapd-calibration\"\nversion = 1\npose = \"";
    out += to_string(cal.pose);
    out += "\"\nheading = \"";
    out += to_string(cal.heading_mode);
    out += "\"\nfacing_heading_rad = ";
    append_double(out, cal.facing_heading_rad);
    out += "\nq_world_earth = ";
    append_quat(out, cal.q_world_earth);
    out += "\n[q_sensor_segment]\n";
    for (std::size_t i = 0; i < std::min(model.size(), cal.segment_count); ++i) {
        if (!cal.calibrated[i]) continue;
        out += model.segments[i].name;
        out += " = ";
        append_quat(out, cal.q_sensor_segment[i]);
    }
    return out;
}

CalibrationResult parse_calibration(const BodyModel& model, std::string_view text) {
    CalibrationResult r;
    if (model.size() > kMaxSegments) {
        r.error = "model has more than " + std::to_string(kMaxSegments) + " segments";
        return r;
    }
    Calibration c;
    c.segment_count = model.size();
    bool in_segments = false;
    bool have_format = false;
    bool have_version = false;
    std::size_t line_no = 0;
    auto fail = [&](const std::string& msg) {
        r.error = "line " + std::to_string(line_no) + ": " + msg;
        return r;
    };
    std::size_t pos = 0;
    while (pos < text.size()) {
        ++line_no;
        std::size_t eol = text.find('\n', pos);
        if (eol == std::string_view::npos) eol = text.size();
        std::string_view line = text.substr(pos, eol - pos);
        pos = eol + 1;
        if (line.size() > 4096) return fail("line too long");
        const std::size_t hash = line.find('#');
        if (hash != std::string_view::npos) line = line.substr(0, hash);
        line = trim(line);
        if (line.empty()) continue;
        if (line.front() == '[' && line.find('=') == std::string_view::npos) {
            if (line != "[q_sensor_segment]") return fail("unknown table " + std::string(line.substr(0, 64)));
            if (in_segments) return fail("table [q_sensor_segment] appears twice");
            in_segments = true;
            continue;
        }
        const std::size_t eq = line.find('=');
        if (eq == std::string_view::npos) return fail("expected key = value");
        const std::string_view key = trim(line.substr(0, eq));
        const std::string_view value = trim(line.substr(eq + 1));
        if (in_segments) {
            const int i = model.index_of(key);
            if (i < 0) return fail("unknown segment '" + std::string(key.substr(0, 64)) + "'");
            const auto idx = static_cast<std::size_t>(i);
            if (c.calibrated[idx]) return fail("segment '" + std::string(key) + "' listed twice");
            Quat q;
            const std::string e = parse_quat(value, q);
            if (!e.empty()) return fail(std::string(key) + ": " + e);
            c.q_sensor_segment[idx] = q;
            c.calibrated[idx] = true;
            continue;
        }
        std::string_view sv;
        if (key == "format") {
            if (!parse_string(value, sv) || sv != "mocapd-calibration")
                return fail("format must be \"mocapd-calibration\"");
            have_format = true;
        } else if (key == "version") {
            double v = 0;
            if (!parse_number(value, v) || v != 1.0) return fail("unsupported version (this build reads 1)");
            have_version = true;
        } else if (key == "pose") {
            if (!parse_string(value, sv)) return fail("pose must be a string");
            if (sv == "t-pose") {
                c.pose = CalibrationPose::kTPose;
            } else if (sv == "n-pose") {
                c.pose = CalibrationPose::kNPose;
            } else if (sv == "custom") {
                c.pose = CalibrationPose::kCustom;
            } else {
                return fail("pose must be \"t-pose\", \"n-pose\" or \"custom\"");
            }
        } else if (key == "heading") {
            if (!parse_string(value, sv) || (sv != "align" && sv != "earth")) {
                return fail("heading must be \"align\" or \"earth\"");
            }
            c.heading_mode = sv == "earth" ? HeadingMode::kKeepEarth : HeadingMode::kAlignToForward;
        } else if (key == "facing_heading_rad") {
            if (!parse_number(value, c.facing_heading_rad)) return fail("facing_heading_rad must be a finite number");
        } else if (key == "q_world_earth") {
            const std::string e = parse_quat(value, c.q_world_earth);
            if (!e.empty()) return fail("q_world_earth: " + e);
        } else {
            return fail("unknown key '" + std::string(key.substr(0, 64)) + "'");
        }
    }
    if (!have_format || !have_version) {
        r.error = "not a mocapd calibration (format and version keys missing)";
        return r;
    }
    r.calibration = c;
    return r;
}

// --- stillness ---------------------------------------------------------------------------

bool StillnessDetector::update(std::int64_t t_us, const Quat& q_earth_sensor, double gyro_norm_rad_s) {
    const Quat q = q_earth_sensor.normalized();
    const bool restart = !started_ || t_us < last_us_ || gyro_norm_rad_s > params_.gyro_threshold_rad_s ||
                         math::angle_rad(anchor_.conjugate() * q) > params_.orientation_threshold_rad;
    if (restart) {
        anchor_ = q;
        since_us_ = t_us;
        started_ = true;
    }
    last_us_ = t_us;
    return still();
}

}  // namespace mocap::skeleton
