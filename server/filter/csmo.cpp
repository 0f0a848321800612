#include "filter/csmo.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace mocap::filter {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

math::Quat initial_estimate(const CsmoParams& p) {
    const math::Quat q(p.q0w, p.q0x, p.q0y, p.q0z);
    const double n = q.norm();
    // An all-zero or non-finite q0 is a configuration error; identity is the safe reading.
    return (n > 0.0 && std::isfinite(n)) ? math::Quat(q.coeffs() / n) : math::Quat::Identity();
}

}  // namespace

Csmo::Csmo(const CsmoParams& params)
    : params_(params),
      k_switch_(params.k1, params.k2, params.k3),
      k_linear_(params.k4, params.k5, params.k6),
      fixed_dip_(std::isfinite(params.dip_deg)),
      h_ref_fixed_(field_direction_enu(fixed_dip_ ? params.dip_deg * kDegToRad : 0.0)),
      clock_(params.max_step_s) {
    lma_.lambda = params.lm_lambda;
    lma_.alpha = params.lm_alpha;
    lma_.max_iterations = std::max(1, params.lm_iterations);
    // Warm-started inside a filter, a tight tolerance only costs iterations.
    lma_.tolerance_rad = 1e-6;
    reset();
}

void Csmo::reset() {
    state_ = CsmoState{};
    state_.q_earth_sensor = initial_estimate(params_);
    state_.q_measured = state_.q_earth_sensor;
    clock_.reset();
}

void Csmo::set_orientation(const math::Quat& q_earth_sensor) {
    state_.q_earth_sensor = math::canonical(q_earth_sensor.normalized());
}

bool Csmo::measure(const ImuSample& sample, const math::Quat& start, math::Quat& q_m) const {
    if (!sample.has_mag()) return false;
    const math::Vec3 a = math::to_vec3(sample.accel_m_s2), m = math::to_vec3(sample.mag_ut);
    math::Vec3 h_ref = h_ref_fixed_;
    if (!fixed_dip_ && !own_dip_field_direction(a, m, h_ref)) return false;
    const AttitudeSolution s = solve_lma(a, m, h_ref, start, lma_);
    if (!s.ok()) return false;
    q_m = s.q_earth_sensor;
    return true;
}

void Csmo::update(const ImuSample& sample) {
    const double dt = clock_.step_s(sample.t_us);
    if (!state_.initialised) {
        state_.initialised = true;
        if (params_.init_from_measurement && sample.has_mag()) {
            // TRIAD only uses the reference field's horizontal direction: any dip will do.
            const AttitudeSolution s = solve_triad(math::to_vec3(sample.accel_m_s2), math::to_vec3(sample.mag_ut),
                                                   field_direction_enu(0.0), lma_);
            if (s.ok()) state_.q_earth_sensor = state_.q_measured = s.q_earth_sensor;
        }
        return;
    }
    if (dt <= 0.0) return;  // gap: restart the time base only

    const math::Vec3 gyro = math::to_vec3(sample.gyro_rad_s);
    if (!gyro.allFinite()) {
        ++state_.rejected_measurements;
        return;
    }
    math::Quat q = state_.q_earth_sensor * math::quat_from_rotvec(gyro * dt);

    math::Quat q_m;
    if (measure(sample, q, q_m)) {
        math::Quat q_e = q.conjugate() * q_m;
        if (q_e.w() < 0.0) q_e.coeffs() = -q_e.coeffs();
        const math::Vec3 e = q_e.vec();
        const double s = dt * params_.gain_rate_hz;
        const math::Vec3 sat = (e / params_.rho).cwiseMax(-1.0).cwiseMin(1.0);
        const math::Vec3 c = s * (k_switch_.cwiseProduct(sat) + k_linear_.cwiseProduct(e));
        q = q * math::Quat(1.0, c.x(), c.y(), c.z());
        state_.q_measured = q_m;
        state_.q_error_vec = e;
    } else {
        ++state_.rejected_measurements;
    }
    state_.q_earth_sensor = q.normalized();
}

}  // namespace mocap::filter
