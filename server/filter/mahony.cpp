#include "filter/mahony.hpp"

#include "filter/marg.hpp"
#include "math/nwu_frame.hpp"

namespace mocap::filter {
std::string MahonyParams::check() const {
    if (!(kp >= 0.0)) return "kp must be >= 0";
    if (!(ki >= 0.0)) return "ki must be >= 0";
    if (!(bias_clip_rad_s >= 0.0)) return "bias_clip_rad_s must be >= 0";
    if (!(max_step_s > 0.0)) return "max_step_s must be > 0";
    return {};
}

MahonyFilter::MahonyFilter(const MahonyParams& params) : params_(params) {
    reset();
}

void MahonyFilter::reset() {
    state_ = MahonyState{};
    state_.clock = SampleClock(params_.max_step_s);
    state_.q_nwu_sensor = math::nwu_from_enu(math::Quat::Identity());
}

void MahonyFilter::update(const ImuSample& sample) {
    MahonyState& st = state_;
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
    math::Vec3 w = math::to_vec3(sample.gyro_rad_s);
    if (m.accel_ok) {
        // Measured × predicted direction, in sensor axes.
        math::Vec3 e = m.accel_m_s2.normalized().cross(math::rotate(q.conjugate(), math::Vec3::UnitZ()));
        if (m.mag_ok) {
            const math::Vec3 mag = m.mag_ut.normalized();
            e += mag.cross(math::rotate(q.conjugate(), math::nwu_field_reference(q, mag)));
        }
        if (params_.ki > 0.0) {
            const double c = params_.bias_clip_rad_s;
            st.integral_rad_s = (st.integral_rad_s + params_.ki * e * dt).cwiseMax(-c).cwiseMin(c);
        } else {
            st.integral_rad_s.setZero();
        }
        w += params_.kp * e + st.integral_rad_s;
    } else {
        w += st.integral_rad_s;
    }
    q = (q * math::quat_from_rotvec(w * dt)).normalized();
}

math::Quat MahonyFilter::orientation() const {
    return (math::q_enu_nwu() * state_.q_nwu_sensor).normalized();
}

}  // namespace mocap::filter
