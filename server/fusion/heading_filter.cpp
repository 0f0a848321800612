#include "fusion/heading_filter.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "math/quaternion.hpp"

namespace mocap::fusion {
namespace {
constexpr double kDeg = std::numbers::pi / 180.0;
}  // namespace

void HeadingFilter::reset() {
    initialised_ = false;
    delta_ = rate_ = 0.0;
    p00_ = p01_ = p11_ = 0.0;
}

void HeadingFilter::init(double delta_rad, double sigma_rad) {
    initialised_ = true;
    delta_ = math::wrap_pi(delta_rad);
    rate_ = 0.0;
    p00_ = sigma_rad * sigma_rad;
    p01_ = 0.0;
    const double rs = params_.rate_sigma_init_deg_s * kDeg;
    p11_ = rs * rs;
}

void HeadingFilter::restart(double delta_rad, double sigma_rad) {
    if (!initialised_) {
        init(delta_rad, sigma_rad);
        return;
    }
    delta_ = math::wrap_pi(delta_rad);
    p00_ = sigma_rad * sigma_rad;
    p01_ = 0.0;
}

double HeadingFilter::sigma_rad() const {
    return initialised_ ? std::sqrt(std::max(p00_, 0.0)) : std::numbers::pi;
}

void HeadingFilter::shift(double d_rad) {
    delta_ = math::wrap_pi(delta_ + d_rad);
}

void HeadingFilter::predict(double dt_s) {
    if (!initialised_ || !(dt_s > 0.0)) return;
    delta_ = math::wrap_pi(delta_ + rate_ * dt_s);
    // P <- F P F' with F = [[1, dt], [0, 1]], plus the random walks.
    const double sd = params_.sigma_delta_deg_sqrt_s * kDeg;
    const double sr = params_.sigma_rate_deg_s_sqrt_s * kDeg;
    p00_ += dt_s * (2.0 * p01_ + dt_s * p11_) + sd * sd * dt_s;
    p01_ += dt_s * p11_;
    p11_ += sr * sr * dt_s;
    // A joint that goes unobserved for a long time: δ's uncertainty saturates, so a later
    // measurement is taken at once rather than after the variance has run away.
    const double smax = params_.sigma_max_deg * kDeg;
    const double pmax = smax * smax;
    if (p00_ > pmax) {
        const double s = std::sqrt(pmax / p00_);
        p00_ = pmax;
        p01_ *= s;
    }
    const double rs0 = params_.rate_sigma_init_deg_s * kDeg;
    p11_ = std::min(p11_, rs0 * rs0);
}

bool HeadingFilter::update(double z_rad, double var_rad2, double gate_sigma) {
    if (!initialised_ || !(var_rad2 > 0.0)) return false;
    const double innov = math::wrap_pi(z_rad - delta_);
    const double s = p00_ + var_rad2;
    if (innov * innov > gate_sigma * gate_sigma * s) {
        ++refused_;
        return false;
    }
    const double k0 = p00_ / s, k1 = p01_ / s;
    delta_ = math::wrap_pi(delta_ + k0 * innov);
    const double rmax = params_.rate_max_deg_s * kDeg;
    rate_ = std::clamp(rate_ + k1 * innov, -rmax, rmax);
    // P <- (I - K H) P with H = [1, 0]
    const double p00 = p00_, p01 = p01_;
    p00_ -= k0 * p00;
    p01_ -= k0 * p01;
    p11_ -= k1 * p01;
    return true;
}

}  // namespace mocap::fusion
