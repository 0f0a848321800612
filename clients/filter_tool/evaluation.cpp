#include "filter_tool/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <numbers>

namespace mocap::tools {

namespace {
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

double rms_deg(double sum_sq_rad, std::size_t n) {
    return n == 0 ? 0.0 : std::sqrt(sum_sq_rad / static_cast<double>(n)) * kRadToDeg;
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
        const Quat q_err = math::mul(s.q_est, math::conj(s.q_ref));
        const double total = math::error_total_rad(q_err);
        if (total >= threshold_rad) {
            last_above = i;
        } else if (!r.first_below_s) {
            r.first_below_s = s.t_s - samples.front().t_s;
        }
        if (!s.evaluated) continue;
        const math::EulerZyx e = math::to_euler_zyx(s.q_est);
        const math::EulerZyx f = math::to_euler_zyx(s.q_ref);
        const double heading = math::error_heading_rad(q_err);
        const double incl = math::error_inclination_rad(q_err);
        const double d_roll = math::wrap_pi(e.roll_rad - f.roll_rad);
        const double d_pitch = math::wrap_pi(e.pitch_rad - f.pitch_rad);
        const double d_yaw = math::wrap_pi(e.yaw_rad - f.yaw_rad);
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
    // JSON has no NaN/Inf: nlohmann writes a non-finite number as null, as it does an
    // absent optional.
    auto opt = [](const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); };
    const nlohmann::ordered_json j{{"rmse_total_deg", r.rmse_total_deg},
                                   {"rmse_heading_deg", r.rmse_heading_deg},
                                   {"rmse_inclination_deg", r.rmse_inclination_deg},
                                   {"rmse_roll_deg", r.rmse_roll_deg},
                                   {"rmse_pitch_deg", r.rmse_pitch_deg},
                                   {"rmse_yaw_deg", r.rmse_yaw_deg},
                                   {"max_total_deg", r.max_total_deg},
                                   {"samples", r.samples},
                                   {"convergence_time_s", opt(r.convergence_time_s)},
                                   {"first_below_s", opt(r.first_below_s)},
                                   {"convergence_threshold_deg", r.convergence_threshold_deg},
                                   {"filter", filter_name}};
    // The filter name comes from the command line: invalid UTF-8 becomes U+FFFD.
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace mocap::tools
