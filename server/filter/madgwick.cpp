#include "filter/madgwick.hpp"

#include "filter/marg.hpp"
#include "math/nwu_frame.hpp"

namespace mocap::filter {
namespace {

// Gradient J^T f of ½|f|², f(q) = q* ⊗ d ⊗ q − s, with respect to the four components of q
// (d: earth reference, s: measurement, both unit). Expanding ½|f|² gives
// ½|d|²|q|⁴ − ⟨d, q ⊗ s ⊗ q*⟩ + const, whose gradient is 2|q|²q + 2 d ⊗ q ⊗ s; this is the
// same vector as the paper's hand-expanded Jacobian products, in a form valid for any d.
math::Vec4 alignment_gradient(const math::Quat& q, const math::Vec3& d, const math::Vec3& s) {
    const math::Quat dq = math::Quat(0.0, d.x(), d.y(), d.z()) * q * math::Quat(0.0, s.x(), s.y(), s.z());
    return 2.0 * q.squaredNorm() * math::to_wxyz(q) + 2.0 * math::to_wxyz(dq);
}

}  // namespace

std::string MadgwickParams::check() const {
    if (!(beta >= 0.0)) return "beta must be >= 0";
    if (!(max_step_s > 0.0)) return "max_step_s must be > 0";
    return {};
}

MadgwickFilter::MadgwickFilter(const MadgwickParams& params) : params_(params) {
    reset();
}

void MadgwickFilter::reset() {
    state_ = MadgwickState{};
    state_.clock = SampleClock(params_.max_step_s);
    state_.q_nwu_sensor = math::nwu_from_enu(math::Quat::Identity());
}

void MadgwickFilter::update(const ImuSample& sample) {
    MadgwickState& st = state_;
    const double dt = st.clock.step_s(sample.t_us);
    const MargReading m = read_marg(sample);
    if (!st.initialised) {
        st.initialised = true;
        // The closed-form attitude of the first reading if wanted and possible, else the ENU identity.
        const bool closed_form = params_.init_from_first_sample && m.accel_ok;
        st.q_nwu_sensor = math::nwu_from_enu(closed_form ? attitude_from_accel_mag(m.accel_m_s2, m.mag_ut, m.mag_ok)
                                                         : math::Quat::Identity());
        return;
    }
    if (dt <= 0.0) return;

    math::Quat& q = st.q_nwu_sensor;
    const math::Vec3 w = math::to_vec3(sample.gyro_rad_s);
    math::Vec4 q_dot = 0.5 * math::to_wxyz(q * math::Quat(0.0, w.x(), w.y(), w.z()));
    if (m.accel_ok) {
        math::Vec4 grad = alignment_gradient(q, math::Vec3::UnitZ(), m.accel_m_s2.normalized());
        if (m.mag_ok) {
            const math::Vec3 mag = m.mag_ut.normalized();
            grad += alignment_gradient(q, math::nwu_field_reference(q, mag), mag);
        }
        const double n = grad.norm();
        if (n > 0.0) q_dot -= params_.beta * grad / n;
    }
    q = math::from_wxyz(math::to_wxyz(q) + q_dot * dt).normalized();
}

math::Quat MadgwickFilter::orientation() const {
    return (math::q_enu_nwu() * state_.q_nwu_sensor).normalized();
}

}  // namespace mocap::filter
