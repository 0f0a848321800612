#include "filter_tool/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace mocap::tools {

namespace {
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

double rms_deg(double sum_sq_rad, std::size_t n) {
    return n == 0 ? 0.0 : std::sqrt(sum_sq_rad / static_cast<double>(n)) * kRadToDeg;
}

// JSON has no NaN/Inf; a number that is not finite is written as null.
void append_number(std::string& out, const char* key, double v) {
    char buf[96];
    if (std::isfinite(v)) {
        std::snprintf(buf, sizeof buf, "\"%s\":%.6g", key, v);
    } else {
        std::snprintf(buf, sizeof buf, "\"%s\":null", key);
    }
    out += buf;
}

void append_json_string(std::string& out, std::string_view s) {
    out += '"';
    for (const char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
            out += buf;
        } else {
            out += c;
        }
    }
    out += '"';
}
}  // namespace

EvalResult evaluate(std::span<const EvalSample> samples, double convergence_threshold_deg) {
    EvalResult r;
    r.convergence_threshold_deg = convergence_threshold_deg;
    double s_total = 0, s_heading = 0, s_incl = 0, s_roll = 0, s_pitch = 0, s_yaw = 0;
    const double threshold_rad = convergence_threshold_deg / kRadToDeg;
    // The convergence instant is the sample after the last one above the threshold.
    std::optional<std::size_t> last_above;
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const EvalSample& s = samples[i];
        if (!s.has_reference) continue;
        const Quat q_err = filter::mul(s.q_est, filter::conj(s.q_ref));
        const double total = filter::error_total_rad(q_err);
        if (total >= threshold_rad) {
            last_above = i;
        } else if (!r.first_below_s) {
            r.first_below_s = s.t_s - samples.front().t_s;
        }
        if (!s.evaluated) continue;
        const filter::EulerZyx e = filter::to_euler_zyx(s.q_est);
        const filter::EulerZyx f = filter::to_euler_zyx(s.q_ref);
        const double heading = filter::error_heading_rad(q_err);
        const double incl = filter::error_inclination_rad(q_err);
        const double d_roll = filter::wrap_pi(e.roll_rad - f.roll_rad);
        const double d_pitch = filter::wrap_pi(e.pitch_rad - f.pitch_rad);
        const double d_yaw = filter::wrap_pi(e.yaw_rad - f.yaw_rad);
        s_total += total * total;
        s_heading += heading * heading;
        s_incl += incl * incl;
        s_roll += d_roll * d_roll;
        s_pitch += d_pitch * d_pitch;
        s_yaw += d_yaw * d_yaw;
        r.max_total_deg = std::max(r.max_total_deg, total * kRadToDeg);
        ++r.samples;
    }
    r.rmse_total_deg = rms_deg(s_total, r.samples);
    r.rmse_heading_deg = rms_deg(s_heading, r.samples);
    r.rmse_inclination_deg = rms_deg(s_incl, r.samples);
    r.rmse_roll_deg = rms_deg(s_roll, r.samples);
    r.rmse_pitch_deg = rms_deg(s_pitch, r.samples);
    r.rmse_yaw_deg = rms_deg(s_yaw, r.samples);
    if (!samples.empty()) {
        if (!last_above) {
            r.convergence_time_s = 0.0;
        } else if (*last_above + 1 < samples.size()) {
            r.convergence_time_s = samples[*last_above + 1].t_s - samples.front().t_s;
        }
    }
    return r;
}

std::string eval_json(const EvalResult& r, std::string_view filter_name) {
    std::string out = "{";
    append_number(out, "rmse_total_deg", r.rmse_total_deg);
    out += ',';
    append_number(out, "rmse_heading_deg", r.rmse_heading_deg);
    out += ',';
    append_number(out, "rmse_inclination_deg", r.rmse_inclination_deg);
    out += ',';
    append_number(out, "rmse_roll_deg", r.rmse_roll_deg);
    out += ',';
    append_number(out, "rmse_pitch_deg", r.rmse_pitch_deg);
    out += ',';
    append_number(out, "rmse_yaw_deg", r.rmse_yaw_deg);
    out += ',';
    append_number(out, "max_total_deg", r.max_total_deg);
    out += ",\"samples\":" + std::to_string(r.samples) + ',';
    append_number(out, "convergence_time_s",
                  r.convergence_time_s ? *r.convergence_time_s : std::numeric_limits<double>::quiet_NaN());
    out += ',';
    append_number(out, "first_below_s", r.first_below_s ? *r.first_below_s : std::numeric_limits<double>::quiet_NaN());
    out += ',';
    append_number(out, "convergence_threshold_deg", r.convergence_threshold_deg);
    out += ",\"filter\":";
    append_json_string(out, filter_name);
    out += '}';
    return out;
}

}  // namespace mocap::tools
