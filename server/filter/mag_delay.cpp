#include "filter/mag_delay.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "math/quaternion.hpp"

namespace mocap::filter {
namespace {

/// The magnetometer reading at t_i + delay for every sample i; nullopt-like flag per sample.
struct Advanced {
    std::vector<math::Vec3> mag_ut;
    std::vector<bool> ok;
};

Advanced advance(std::span<const ImuSample> samples, double delay_s) {
    const std::size_t n = samples.size();
    Advanced a{std::vector<math::Vec3>(n, math::Vec3::Zero()), std::vector<bool>(n, false)};
    const auto delay_us = static_cast<std::int64_t>(std::llround(delay_s * 1e6));
    std::size_t j = 0;  // samples[j].t_us <= t < samples[j + 1].t_us
    for (std::size_t i = 0; i < n; ++i) {
        const std::int64_t t = samples[i].t_us + delay_us;
        while (j + 1 < n && samples[j + 1].t_us <= t)
            ++j;
        if (j + 1 >= n || samples[j].t_us >= t) {
            // At or past the last reading, or exactly on one: that reading.
            a.mag_ut[i] = math::to_vec3(samples[j].mag_ut);
            a.ok[i] = samples[j].has_mag();
            continue;
        }
        const ImuSample& s0 = samples[j];
        const ImuSample& s1 = samples[j + 1];
        const double f = static_cast<double>(t - s0.t_us) / static_cast<double>(s1.t_us - s0.t_us);
        a.mag_ut[i] = (1.0 - f) * math::to_vec3(s0.mag_ut) + f * math::to_vec3(s1.mag_ut);
        a.ok[i] = s0.has_mag() && s1.has_mag();
    }
    return a;
}

/// Mean |dm/dt + ω × m|² over the turning samples with the field read delay_s later.
double lag_cost(std::span<const ImuSample> samples, double delay_s, double min_rate_rad_s, std::size_t& used) {
    const Advanced a = advance(samples, delay_s);
    double sum = 0.0;
    used = 0;
    for (std::size_t i = 1; i + 1 < samples.size(); ++i) {
        if (!a.ok[i - 1] || !a.ok[i] || !a.ok[i + 1]) continue;
        const math::Vec3 w = math::to_vec3(samples[i].gyro_rad_s);
        if (w.norm() < min_rate_rad_s) continue;
        const double span_s = static_cast<double>(samples[i + 1].t_us - samples[i - 1].t_us) * 1e-6;
        const math::Vec3 dm = (a.mag_ut[i + 1] - a.mag_ut[i - 1]) / span_s;
        sum += (dm + w.cross(a.mag_ut[i])).squaredNorm();
        ++used;
    }
    return used > 0 ? sum / static_cast<double>(used) : std::numeric_limits<double>::infinity();
}

}  // namespace

MagDelayEstimate estimate_mag_delay(std::span<const ImuSample> samples, double max_delay_s, double min_rate_rad_s) {
    MagDelayEstimate est;
    if (samples.size() < 3 || max_delay_s <= 0.0) return est;
    std::vector<std::int64_t> steps;
    steps.reserve(samples.size() - 1);
    for (std::size_t i = 1; i < samples.size(); ++i)
        steps.push_back(samples[i].t_us - samples[i - 1].t_us);
    std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
    const double ts_s = static_cast<double>(steps[steps.size() / 2]) * 1e-6;
    if (ts_s <= 0.0) return est;

    // Shifts of -1 .. K sample periods: -1 lets a field that is not late at all (shift -0.5,
    // below) be found.
    const auto candidates = static_cast<std::size_t>(std::floor(max_delay_s / ts_s)) + 2;
    std::vector<double> cost(candidates);
    std::size_t used = 0;
    for (std::size_t k = 0; k < candidates; ++k) {
        cost[k] = lag_cost(samples, (static_cast<double>(k) - 1.0) * ts_s, min_rate_rad_s, used);
    }
    if (used < 100) return est;
    const auto best = static_cast<std::size_t>(std::min_element(cost.begin(), cost.end()) - cost.begin());
    double shift = static_cast<double>(best) - 1.0;
    if (best > 0 && best + 1 < candidates) {
        const double c0 = cost[best - 1], c1 = cost[best], c2 = cost[best + 1];
        const double curvature = c0 - 2.0 * c1 + c2;
        if (curvature > 0.0) shift += 0.5 * (c0 - c2) / curvature;
    }
    // A gyro reading covers the step before its timestamp (the filters integrate it over
    // (t_prev, t]): it is the rate half a step earlier, so the field pairs with it half a step
    // before the sample's time.
    est.delay_s = std::clamp((shift + 0.5) * ts_s, 0.0, max_delay_s);
    est.samples = used;
    return est;
}

std::vector<ImuSample> advance_mag(std::span<const ImuSample> samples, double delay_s) {
    const Advanced a = advance(samples, delay_s);
    std::vector<ImuSample> out(samples.begin(), samples.end());
    for (std::size_t i = 0; i < out.size(); ++i) {
        out[i].mag_ut = math::to_array(a.mag_ut[i]);
        if (a.ok[i]) {
            out[i].flags = static_cast<std::uint8_t>(out[i].flags & ~kImuNoMag);
        } else {
            out[i].flags = static_cast<std::uint8_t>(out[i].flags | kImuNoMag);
        }
    }
    return out;
}

math::Vec3 mag_ahead(const math::Vec3& mag_ut, const math::Vec3& gyro_rad_s, double delay_s) {
    return math::rotate(math::quat_from_rotvec(-delay_s * gyro_rad_s), mag_ut);
}

void MagDelayTracker::update(const math::Vec3& gyro_rad_s, const math::Vec3& mag_ut, bool mag_ok, double dt_s,
                             bool usable, double forgetting) {
    if (!mag_ok || dt_s <= 0.0) {
        history_ = 0;
        if (!mag_ok) return;
    }
    // Central differences need two equal steps; a step that differs by over 10 % (a dropped
    // sample) restarts the history instead.
    if (history_ == 2 && std::abs(dt_s - dt_prev_s_) <= 0.1 * dt_prev_s_) {
        const double span_s = dt_s + dt_prev_s_;
        const math::Vec3 w = 0.5 * (gyro_rad_s + gyro_[0]);
        if (usable && w.norm() >= kMagDelayMinRateRadS) {
            const math::Vec3 r = (mag_ut - mag_[1]) / span_s + w.cross(mag_[0]);
            const math::Vec3 g = ((gyro_rad_s - gyro_[1]) / span_s).cross(mag_[0]);
            n_ = forgetting * n_ + 1.0;
            turning_s_ = forgetting * turning_s_ + dt_s;
            sgg_ = forgetting * sgg_ + g.squaredNorm();
            sgr_ = forgetting * sgr_ + g.dot(r);
            srr_ = forgetting * srr_ + r.squaredNorm();
            const double se = std_error_s();
            if (turning_s_ >= kMinTurningS && se < kConvergedStdErrS) converged_ = true;
            if (se > 2.0 * kConvergedStdErrS) converged_ = false;
        }
    }
    gyro_[1] = gyro_[0];
    gyro_[0] = gyro_rad_s;
    mag_[1] = mag_[0];
    mag_[0] = mag_ut;
    dt_prev_s_ = dt_s;
    history_ = std::min(history_ + 1, 2);
}

double MagDelayTracker::std_error_s() const {
    if (n_ <= 1.0 || sgg_ <= 0.0) return std::numeric_limits<double>::infinity();
    // Residual variance per sample (Σ r² − d Σ g·r = Σ (r − d g)² at the optimum).
    const double residual = std::max(srr_ - sgr_ * sgr_ / sgg_, 0.0) / n_;
    return std::sqrt(residual / sgg_);
}

double MagDelayTracker::delay_s(double max_delay_s) const {
    return converged() ? std::clamp(estimate_s(), 0.0, max_delay_s) : 0.0;
}

}  // namespace mocap::filter
