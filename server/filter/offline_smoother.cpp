#include "filter/offline_smoother.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>

#include "filter/mag_delay.hpp"
#include "math/markley_average.hpp"

namespace mocap::filter {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

/// One pass over the recording, per sample.
struct PassOutput {
    std::vector<math::Quat> q;         ///< the filter's estimate after the sample
    std::vector<double> run_s;         ///< time the pass had run
    std::vector<double> residual_rad;  ///< heading of the field reading seen through q
    std::vector<char> field_clean;     ///< a reading the filter took as undisturbed (norm and dip)
    std::vector<char> mag_used;        ///< a reading the filter used for heading (not rejected)
};

/// Runs `filter` over the samples in the order of `forward`: true from the first sample to
/// the last, false from the last to the first. A backward step plays the interval it crosses
/// in reverse: the gyro reading that covered it, negated, on a time base that advances by
/// the recording's own steps (so a gap stays a gap).
PassOutput run_pass(OrientationFilter& filter, std::span<const ImuSample> samples, bool forward) {
    const std::size_t n = samples.size();
    PassOutput out{std::vector<math::Quat>(n), std::vector<double>(n), std::vector<double>(n), std::vector<char>(n),
                   std::vector<char>(n)};
    filter.reset();
    std::int64_t t_us = samples[forward ? 0 : n - 1].t_us;
    double run_s = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = forward ? k : n - 1 - k;
        ImuSample s = samples[i];
        if (!forward) {
            if (k > 0) {
                const ImuSample& later = samples[i + 1];  // its gyro reading covers (t_i, t_i+1]
                const std::int64_t d_us = later.t_us - s.t_us;
                t_us += d_us;
                run_s += static_cast<double>(d_us) * 1e-6;
                s.gyro_rad_s = math::to_array(-math::to_vec3(later.gyro_rad_s));
            }
            s.t_us = t_us;
        } else if (k > 0) {
            run_s += static_cast<double>(s.t_us - samples[i - 1].t_us) * 1e-6;
        }
        filter.update(s);
        const FilterDiagnostics d = filter.diagnostics();
        const math::Quat q = filter.orientation();
        // The filter's earth frame has the horizontal field on +y (magnetic north): the
        // residual is the heading of the reading, less any offset the filter subtracts.
        const math::Vec3 h = math::rotate(q, math::to_vec3(s.mag_ut) - d.mag_offset_weight * d.mag_offset_ut);
        out.q[i] = q;
        out.run_s[i] = run_s;
        out.field_clean[i] = s.has_mag() && !d.mag_field_disturbed && (h.x() != 0.0 || h.y() != 0.0);
        out.mag_used[i] = s.has_mag() && !d.mag_rejected;
        out.residual_rad[i] = out.field_clean[i] ? std::atan2(h.x(), h.y()) : 0.0;
    }
    return out;
}

/// Each pass's heading error variance over ±window_s around every sample, from the heading
/// residuals r_f, r_b of the field readings both passes took as undisturbed by norm and dip
/// and at least one used: a pass far off in heading rejects the clean field as a heading
/// disturbance, and its residual must count against it; a reading both passes rejected
/// (a disturbance norm and dip do not show) tells neither apart. A residual is
/// the field's own heading error φ (noise, motion, calibration, a disturbance the norm and
/// dip do not show), common to both passes, less the pass's error e: r = φ − e. With the
/// passes' errors independent of each other, mean(r_f·r_b) estimates mean(φ²), so a pass's
/// error variance is mean(r²) − mean(r_f·r_b) (clamped at 0; the two add up to
/// mean((r_f − r_b)²), the passes' disagreement): the field's common error no longer evens
/// out the weights of a pass that is off and one that is not. 0 where fewer than one
/// second's worth (or none) of such samples is in the window.
void residual_variances(std::span<const ImuSample> samples, const PassOutput& fwd, const PassOutput& bwd,
                        double window_s, std::vector<double>& var_fwd, std::vector<double>& var_bwd) {
    const std::size_t n = samples.size();
    var_fwd.assign(n, 0.0);
    var_bwd.assign(n, 0.0);
    if (window_s <= 0.0 || n < 2) return;
    // Prefix sums: squared residuals of each pass, their product and the count of usable samples.
    std::vector<double> sf(n + 1, 0.0), sb(n + 1, 0.0), sfb(n + 1, 0.0), count(n + 1, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
        const bool both = fwd.field_clean[i] && bwd.field_clean[i] && (fwd.mag_used[i] || bwd.mag_used[i]);
        const double rf = both ? fwd.residual_rad[i] : 0.0;
        const double rb = both ? bwd.residual_rad[i] : 0.0;
        sf[i + 1] = sf[i] + rf * rf;
        sb[i + 1] = sb[i] + rb * rb;
        sfb[i + 1] = sfb[i] + rf * rb;
        count[i + 1] = count[i] + (both ? 1.0 : 0.0);
    }
    const double span_s = static_cast<double>(samples.back().t_us - samples.front().t_us) * 1e-6;
    const double per_second = static_cast<double>(n - 1) / std::max(span_s, 1e-6);
    const auto window_us = static_cast<std::int64_t>(window_s * 1e6);
    std::size_t lo = 0, hi = 0;  // window [lo, hi)
    for (std::size_t i = 0; i < n; ++i) {
        while (samples[lo].t_us < samples[i].t_us - window_us)
            ++lo;
        while (hi < n && samples[hi].t_us <= samples[i].t_us + window_us)
            ++hi;
        const double c = count[hi] - count[lo];
        if (c < per_second) continue;
        const double common = (sfb[hi] - sfb[lo]) / c;
        var_fwd[i] = std::max(0.0, (sf[hi] - sf[lo]) / c - common);
        var_bwd[i] = std::max(0.0, (sb[hi] - sb[lo]) / c - common);
    }
}

/// The rotation about the vertical that turns the backward pass's heading frame into the
/// forward pass's, when neither pass had a magnetometer to fix it: each pass then keeps the
/// heading of its own first sample, and the two frames are unrelated (up to 180° apart).
/// Both passes integrate the same gyro, so their difference is nearly constant; its circular
/// mean over the samples where both have run past their start-up (all samples, weighted by
/// the shorter run, if the take is too short for that) aligns them.
double backward_heading_offset(const PassOutput& fwd, const PassOutput& bwd, double settled_s) {
    double c = 0.0, s = 0.0, c_all = 0.0, s_all = 0.0;
    for (std::size_t i = 0; i < fwd.q.size(); ++i) {
        const math::Quat d = fwd.q[i] * bwd.q[i].conjugate();
        const double a = 2.0 * std::atan2(d.z(), d.w());  // the part of d about the vertical
        const double w = std::min(fwd.run_s[i], bwd.run_s[i]);
        c_all += w * std::cos(a);
        s_all += w * std::sin(a);
        if (w >= settled_s) {
            c += std::cos(a);
            s += std::sin(a);
        }
    }
    if (c == 0.0 && s == 0.0) return std::atan2(s_all, c_all);
    return std::atan2(s, c);
}

bool used_field(const PassOutput& pass) {
    return std::any_of(pass.mag_used.begin(), pass.mag_used.end(), [](char u) { return u != 0; });
}

}  // namespace

OfflineResult OfflineSmoother::smooth(OrientationFilter& filter, std::span<const ImuSample> samples) const {
    OfflineResult result;
    if (samples.empty()) return result;
    result.mag_delay_s = estimate_mag_delay(samples, params_.mag_delay_max_s).delay_s;
    const std::vector<ImuSample> aligned = advance_mag(samples, result.mag_delay_s);

    const PassOutput fwd = run_pass(filter, aligned, true);
    PassOutput bwd = run_pass(filter, aligned, false);
    const bool no_field = !used_field(fwd) && !used_field(bwd);
    if (no_field) {
        result.backward_heading_offset_rad = backward_heading_offset(fwd, bwd, 2.0 * params_.converge_tau_s);
        const double h = 0.5 * result.backward_heading_offset_rad;
        const math::Quat rz(std::cos(h), 0.0, 0.0, std::sin(h));
        for (math::Quat& q : bwd.q)
            q = (rz * q).normalized();
    }
    std::vector<double> resid_fwd, resid_bwd;
    residual_variances(aligned, fwd, bwd, params_.residual_window_s, resid_fwd, resid_bwd);

    const double floor = params_.sigma_floor_deg * kDeg;
    const double start = params_.sigma_start_deg * kDeg;
    const auto variance = [&](double run_s, double resid) {
        const double s = start * std::exp(-run_s / params_.converge_tau_s);
        return floor * floor + s * s + resid;
    };
    const std::size_t n = aligned.size();
    result.orientation.resize(n);
    result.forward_weight.resize(n);
    result.mag_used.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const double wf = 1.0 / variance(fwd.run_s[i], resid_fwd[i]);
        const double wb = 1.0 / variance(bwd.run_s[i], resid_bwd[i]);
        result.forward_weight[i] = wf / (wf + wb);
        result.orientation[i] = math::average_two(fwd.q[i], wf, bwd.q[i], wb);
        if (no_field) {
            // Without a field only the inclination is blended; the heading stays the forward
            // pass's, the integral of the gyro: the passes' headings drift apart where their
            // tilt corrections differ (large accelerations), and a blend of them would
            // wander by half of that, turning a segment against its neighbours.
            const math::Quat d = fwd.q[i] * result.orientation[i].conjugate();
            const double h = std::atan2(d.z(), d.w());  // half the turn about the vertical
            result.orientation[i] =
                (math::Quat(std::cos(h), 0.0, 0.0, std::sin(h)) * result.orientation[i]).normalized();
        }
        result.mag_used[i] = static_cast<char>(fwd.mag_used[i] || bwd.mag_used[i]);
    }
    return result;
}

}  // namespace mocap::filter
