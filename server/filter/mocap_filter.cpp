#include "filter/mocap_filter.hpp"

#include "filter/marg.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace mocap::filter {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// Magnetometer lag: the longest one taken out, s, and the window of the online estimate, s
// of turning with an undisturbed field (a sensor's lag does not change; a long window keeps
// the estimate steady).
constexpr double kMagDelayMaxS = 0.05;
constexpr double kMagDelayWindowS = 60.0;
// Linear acceleration (header, "Linear acceleration"): the specific force's deviation from the
// low-passed gravity is clipped at kAccClipScales running medians of that deviation, never
// below kAccClipMinM_s2; the median follows the deviation by at most a factor e per
// kAccDevMedianTauS. It is kept at or above the median the smallest clip stands for, so that
// on a quiet sensor a deviation that persists (a low-pass that is itself off) raises the clip
// at once rather than after seconds of climbing from the noise.
constexpr double kAccClipScales = 3.0;
constexpr double kAccClipMinM_s2 = 0.5;
constexpr double kAccDevMedianTauS = 1.0;
constexpr double kAccDevMedianMinM_s2 = kAccClipMinM_s2 / kAccClipScales;
// Heading guard and vertical bias (header, "Vertical gyro bias"): the guard follows a heading
// disagreement that moves by no more than the heading correction and kDriftSigmas standard
// deviations of the vertical bias (as the rest measurements know it) can move it; the field's
// departures from its reference are low-passed over kFieldDevTauS (what a heading correction
// over tau_mag_s averages out faster does not count) before their variance weighs the heading's
// measurement of the bias.
constexpr double kDriftSigmas = 2.0;
constexpr double kFieldDevTauS = 2.0;
// (rad/s)² to the bias filter's units, (0.01 °/s)².
constexpr double kRadS2ToBiasUnits = (100.0 / kDeg) * (100.0 / kDeg);

// Butterworth cut-off chosen so the non-oscillating part of the step response has time
// constant tau (as in VQF). tau <= 0 means "no filtering".
LowPassCoeffs butterworth(double tau_s, double ts_s) {
    LowPassCoeffs c;
    if (tau_s <= 0.0) return c;
    const double fc = (std::numbers::sqrt2 / (2.0 * std::numbers::pi)) / tau_s;
    const double k = std::tan(std::numbers::pi * fc * ts_s);
    const double d = k * k + std::numbers::sqrt2 * k + 1.0;
    const double b0 = k * k / d;
    c.b = {b0, 2.0 * b0, b0};
    c.a = {2.0 * (k * k - 1.0) / d, (1.0 - std::numbers::sqrt2 * k + k * k) / d};
    return c;
}

// One step of the N-channel filter. During the first tau seconds the output is the mean
// of the inputs so far; then the filter starts in steady state on that mean. Until the
// sample period is known (ts_s == 0) it keeps averaging.
template <int N>
void low_pass(LowPassState<N>& s, const double* x, const LowPassCoeffs& c, double tau_s, double ts_s) {
    if (!s.running) {
        ++s.count;
        for (int i = 0; i < N; ++i) {
            s.sum[i] += x[i];
            s.out[i] = s.sum[i] / s.count;
        }
        if (ts_s > 0.0 && s.count * ts_s >= tau_s) {
            s.running = true;
            for (int i = 0; i < N; ++i) {
                s.z[2 * i] = s.out[i] * (1.0 - c.b[0]);
                s.z[2 * i + 1] = s.out[i] * (c.b[2] - c.a[1]);
            }
        }
        return;
    }
    for (int i = 0; i < N; ++i) {
        double* z = &s.z[2 * i];
        const double y = c.b[0] * x[i] + z[0];
        z[0] = c.b[1] * x[i] - c.a[0] * y + z[1];
        z[1] = c.b[2] * x[i] - c.a[1] * y;
        s.out[i] = y;
    }
}

// Heading of the horizontal field h (6D earth frame) less delta, measured as the cross product
// with the expected direction over the mean horizontal field strength h_ref. Unlike the angle of
// each reading, this is unbiased under noise as large as the field itself (the per-reading angle
// wraps around and pulls the average towards zero).
double heading_disagreement(const math::Vec3& h, double delta_rad, double h_ref) {
    const double u_x = std::sin(delta_rad), u_y = std::cos(delta_rad);
    const double dot = h.x() * u_x + h.y() * u_y;
    return dot > 0.0 && h_ref > 0.0
               ? std::clamp((h.x() * u_y - h.y() * u_x) / h_ref, -0.5 * std::numbers::pi, 0.5 * std::numbers::pi)
               : math::wrap_pi(std::atan2(h.x(), h.y()) - delta_rad);
}

math::Vec3 out3(const LowPassState<3>& s) {
    return {s.out[0], s.out[1], s.out[2]};
}

double gain_from_tau(double tau_s, double ts_s) {
    if (tau_s < 0.0) return 0.0;  // disabled
    if (tau_s == 0.0) return 1.0;
    return 1.0 - std::exp(-ts_s / tau_s);
}

}  // namespace

std::string MocapFilterParams::check() const {
    if (!(tau_acc_s > 0.0)) return "tau_acc_s must be > 0";
    if (!(tau_mag_s > 0.0)) return "tau_mag_s must be > 0";
    if (!(bias_sigma_init_deg_s > 0.0)) return "bias_sigma_init_deg_s must be > 0";
    if (!(bias_forgetting_time_s > 0.0)) return "bias_forgetting_time_s must be > 0";
    if (!(bias_clip_deg_s > 0.0)) return "bias_clip_deg_s must be > 0";
    if (!(bias_sigma_motion_deg_s > 0.0)) return "bias_sigma_motion_deg_s must be > 0";
    if (!(bias_vertical_forgetting >= 0.0 && bias_vertical_forgetting <= 1.0))
        return "bias_vertical_forgetting must be in [0, 1]";
    if (!(bias_sigma_rest_deg_s > 0.0)) return "bias_sigma_rest_deg_s must be > 0";
    if (!(rest_min_time_s >= 0.0)) return "rest_min_time_s must be >= 0";
    if (!(rest_filter_tau_s > 0.0)) return "rest_filter_tau_s must be > 0";
    if (!(rest_th_gyro_deg_s > 0.0)) return "rest_th_gyro_deg_s must be > 0";
    if (!(rest_th_acc_m_s2 > 0.0)) return "rest_th_acc_m_s2 must be > 0";
    if (!(mag_current_tau_s >= 0.0)) return "mag_current_tau_s must be >= 0";
    if (!(mag_ref_tau_s > 0.0)) return "mag_ref_tau_s must be > 0";
    if (!(mag_norm_th > 0.0)) return "mag_norm_th must be > 0";
    if (!(mag_dip_th_deg > 0.0)) return "mag_dip_th_deg must be > 0";
    if (!(mag_noise_margin >= 0.0)) return "mag_noise_margin must be >= 0";
    if (!(mag_heading_th_deg >= 0.0)) return "mag_heading_th_deg must be >= 0";
    if (!(mag_heading_tau_s > 0.0)) return "mag_heading_tau_s must be > 0";
    if (!(mag_new_time_s >= 0.0)) return "mag_new_time_s must be >= 0";
    if (!(mag_new_first_time_s >= 0.0)) return "mag_new_first_time_s must be >= 0";
    if (!(mag_new_min_gyro_deg_s >= 0.0)) return "mag_new_min_gyro_deg_s must be >= 0";
    if (!(mag_min_undisturbed_time_s >= 0.0)) return "mag_min_undisturbed_time_s must be >= 0";
    if (!(mag_max_rejection_time_s >= 0.0)) return "mag_max_rejection_time_s must be >= 0";
    if (!(mag_rejection_factor >= 1.0)) return "mag_rejection_factor must be >= 1";
    if (!(gyro_noise_ref_deg_s >= 0.0)) return "gyro_noise_ref_deg_s must be >= 0";
    if (!(mag_offset_tau_s >= 0.0)) return "mag_offset_tau_s must be >= 0";
    if (!(mag_offset_ridge > 0.0 && mag_offset_ridge <= 1.0)) return "mag_offset_ridge must be in (0, 1]";
    if (!(mag_offset_min > 0.0)) return "mag_offset_min must be > 0";
    if (!(mag_delay_s <= kMagDelayMaxS)) return "mag_delay_s must be <= 0.05";
    if (!(mag_delay_share >= 0.0 && mag_delay_share <= 1.0)) return "mag_delay_share must be in [0, 1]";
    if (!(max_step_s > 0.0)) return "max_step_s must be > 0";
    return {};
}

MocapFilter::MocapFilter(const MocapFilterParams& params) : params_(params) {
    reset();
}

void MocapFilter::reset() {
    state_ = MocapFilterState{};
    state_.clock = SampleClock(params_.max_step_s);
    const double p0 = std::pow(params_.bias_sigma_init_deg_s * 100.0, 2);
    state_.bias_p = p0 * math::Mat3::Identity();
    state_.vertical_bias_var = std::pow(params_.bias_clip_deg_s * 100.0, 2);
    state_.tau_acc_eff_s = params_.tau_acc_s;
    state_.tau_mag_eff_s = params_.tau_mag_s;
}

// The time constants trade gyro noise against accelerometer / magnetometer errors. The
// defaults assume a MEMS-class gyro; a gyro whose white-noise floor is far above
// gyro_noise_ref_deg_s is trusted for proportionally less time (tau_acc), and the heading
// time constant moves towards its noise-optimal value σ_heading / σ_gyro (the steady-state
// error of a first-order complementary filter with white noise on both sides is smallest at
// tau = σ_measurement / σ_rate).
void MocapFilter::adapt_time_constants() {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    const double ref = p.gyro_noise_ref_deg_s * kDeg;
    const double sigma_g = std::sqrt(s.gyro_noise_floor_var);
    double tau_acc = p.tau_acc_s, tau_mag = p.tau_mag_s;
    if (ref > 0.0 && s.gyro_noise_count > 0 && sigma_g > ref) {
        tau_acc = p.tau_acc_s * ref / sigma_g;
        const double h_ref2 = s.mag_horizontal_lp.squaredNorm();
        if (h_ref2 > 0.0 && s.mag_noise_var > 0.0) {
            const double sigma_heading = std::sqrt(s.mag_noise_var / h_ref2);
            tau_mag = std::clamp(sigma_heading / sigma_g, std::min(tau_acc, p.tau_mag_s), p.tau_mag_s);
        }
    }
    const auto moved = [](double a, double b) { return std::abs(a - b) > 0.1 * b; };
    if (moved(tau_acc, s.tau_acc_eff_s) || moved(tau_mag, s.tau_mag_eff_s)) {
        s.tau_acc_eff_s = tau_acc;
        s.tau_mag_eff_s = tau_mag;
        compute_coeffs(s.ts_s);
    }
}

void MocapFilter::compute_coeffs(double ts_s) {
    const MocapFilterParams& p = params_;
    state_.ts_s = ts_s;
    acc_lp_ = butterworth(state_.tau_acc_eff_s, ts_s);
    rest_lp_ = butterworth(p.rest_filter_tau_s, ts_s);
    mag_current_lp_ = butterworth(p.mag_current_tau_s, ts_s);
    k_mag_ = gain_from_tau(state_.tau_mag_eff_s, ts_s);
    k_mag_ref_ = gain_from_tau(p.mag_ref_tau_s, ts_s);
    k_mag_noise_ = k_mag_ref_;
    k_dis_ = gain_from_tau(p.mag_heading_tau_s, ts_s);
    k_noise_fast_ = gain_from_tau(1.0, ts_s);
    k_noise_floor_ = gain_from_tau(300.0, ts_s);
    k_mag_offset_ = p.mag_offset_tau_s > 0.0 ? gain_from_tau(p.mag_offset_tau_s, ts_s) : 0.0;
    mag_delay_forgetting_ = std::exp(-ts_s / kMagDelayWindowS);
    acc_dev_median_step_ = std::exp(ts_s / kAccDevMedianTauS);
    // Bias Kalman filter in units of 0.01 °/s, which keeps the numbers near 1.
    bias_p0_ = std::pow(p.bias_sigma_init_deg_s * 100.0, 2);
    vertical_bias_var0_ = std::pow(p.bias_clip_deg_s * 100.0, 2);
    bias_v_ = std::pow(0.1 * p.bias_sigma_init_deg_s * 100.0, 2) * ts_s / p.bias_forgetting_time_s;
    const double p_motion = std::pow(p.bias_sigma_motion_deg_s * 100.0, 2);
    bias_motion_w_ = p_motion * p_motion / bias_v_ + p_motion;
    bias_vertical_w_ = bias_motion_w_ / std::max(p.bias_vertical_forgetting, 1e-10);
    k_field_dev_ = gain_from_tau(kFieldDevTauS, ts_s);
    const double p_rest = std::pow(p.bias_sigma_rest_deg_s * 100.0, 2);
    bias_rest_w_ = p_rest * p_rest / bias_v_ + p_rest;
}

void MocapFilter::update(const ImuSample& sample) {
    MocapFilterState& s = state_;
    const double dt = s.clock.step_s(sample.t_us);
    const math::Vec3 gyro = math::to_vec3(sample.gyro_rad_s);
    ++s.samples;
    if (s.clock.skipped()) restart_attitude();
    if (!s.initialised) {
        s.initialised = true;  // dt == 0: the first sample sets attitude, not motion
    } else if (dt > 0.0) {
        if (s.ts_s == 0.0) {
            s.ts_lp_s = dt;
            compute_coeffs(dt);
        } else {
            s.ts_lp_s += 0.01 * (dt - s.ts_lp_s);
            if (std::abs(s.ts_lp_s - s.ts_s) > 0.02 * s.ts_s) compute_coeffs(s.ts_lp_s);
        }
        update_gyro(gyro, dt);
        adapt_time_constants();
    }
    const math::Vec3 rate = gyro - s.bias_rad_s;
    const MargReading m = read_marg(sample);
    if (m.accel_ok) {
        update_acc(m.accel_m_s2);
    } else {
        ++s.zero_acc_samples;
    }
    if (m.mag_ok) {
        update_mag(m.mag_ut, rate, dt);
    } else {
        ++s.no_mag_samples;
        if (params_.mag_delay_s < 0.0) s.mag_delay.update(rate, m.mag_ut, false, dt, false, mag_delay_forgetting_);
    }
}

// A gap (samples missing for longer than max_step_s): the motion in it was not followed, so
// after it the attitude is off by whatever the sensor turned meanwhile, and everything
// averaged along the attitude is in a frame that no longer holds. Kept, the accelerometer's
// low-pass and the bias measurement built on it took the inclination's catching up for gyro
// bias, and the heading guard took the heading's for a disturbed field: a 2.5 s gap while
// walking left a pelvis 1-2 °/s off about the vertical, its field refused for a minute and the
// hips up to 100° off. So the attitude starts again as at the first sample (inclination from
// the accelerometer, heading from the field's fast start), with what belongs to the sensor and
// its place kept: the gyro bias and its uncertainty, the gyro's noise floor, the sample period
// and time constants, the reference field's norm and dip, the magnetometer's lag.
// heading_split().frame_epoch tells the chain stage that q6's heading frame changed.
void MocapFilter::restart_attitude() {
    MocapFilterState& s = state_;
    s.q_i_sensor = math::Quat::Identity();
    s.q_e6_i = math::Quat::Identity();
    s.delta_rad = 0.0;
    s.initialised = false;  // this sample sets the attitude, not motion
    s.gyro_history = 0;     // second differences across the gap are not noise
    s.acc_lp = {};
    s.acc_clip = 1.0;
    s.bias_r_lp = {};
    s.bias_b_lp = {};
    s.rest_time_s = 0.0;
    s.rest_detected = false;
    // The field in the 6D frame, and the heading's statistics against it, start again.
    s.mag_lp = {};
    s.mag_dis_lp_rad = s.mag_dis_drift_rad = 0.0;
    s.field_dir_lp.setZero();
    s.mag_heading_disturbed = false;
    s.mag_settled = true;
    s.k_mag_init = 1.0;
    s.last_mag_disagreement_rad = 0.0;
    s.mag_horizontal_lp.setZero();
    s.mag_reject_time_s = 0.0;
    s.hb_running = false;
    s.mag_off_n = 0.0;
    s.mag_off_r.setZero();
    s.mag_off_sum_e.setZero();
    s.mag_off_sum_s.setZero();
    ++s.attitude_restarts;
}

void MocapFilter::update_gyro(const math::Vec3& gyro, double dt_s) {
    MocapFilterState& s = state_;
    if (params_.rest_bias || params_.mag_guard) {
        low_pass(s.rest_gyro_lp, gyro.data(), rest_lp_, params_.rest_filter_tau_s, s.ts_s);
        const math::Vec3 lp = out3(s.rest_gyro_lp);
        const double th = params_.rest_th_gyro_deg_s * kDeg;
        const double clip = params_.bias_clip_deg_s * kDeg;
        if ((gyro - lp).squaredNorm() >= th * th || lp.cwiseAbs().maxCoeff() > clip) {
            s.rest_time_s = 0.0;
            s.rest_detected = false;
        }
    }
    // White-noise floor of the gyro: second differences cancel smooth motion and keep
    // 6σ² of white noise; their 1 s low-pass is tracked downwards at once and upwards over
    // 300 s, so the floor comes from the quietest stretch of the last minutes and minutes of
    // vigorous motion (whose second differences are large at 100 Hz) do not raise it much.
    if (s.gyro_history >= 2) {
        const math::Vec3 d2 = gyro - 2.0 * s.gyro_prev[0] + s.gyro_prev[1];
        const double v = d2.squaredNorm() / 18.0;  // per axis: 3 axes × 6σ²
        ++s.gyro_noise_count;
        const double k_fast = std::max(k_noise_fast_, 1.0 / static_cast<double>(s.gyro_noise_count));
        s.gyro_noise_var_lp += k_fast * (v - s.gyro_noise_var_lp);
        // The first second is a plain mean: a minimum over it would catch a lucky sample.
        const bool averaging = static_cast<double>(s.gyro_noise_count) * s.ts_s < 1.0;
        if (averaging || s.gyro_noise_var_lp < s.gyro_noise_floor_var) {
            s.gyro_noise_floor_var = s.gyro_noise_var_lp;
        } else {
            s.gyro_noise_floor_var += k_noise_floor_ * (s.gyro_noise_var_lp - s.gyro_noise_floor_var);
        }
    }
    s.gyro_prev[1] = s.gyro_prev[0];
    s.gyro_prev[0] = gyro;
    s.gyro_history = std::min(s.gyro_history + 1, 2);

    const math::Vec3 w = gyro - s.bias_rad_s;
    s.q_i_sensor = (s.q_i_sensor * math::quat_from_rotvec(w * dt_s)).normalized();
}

void MocapFilter::update_acc(const math::Vec3& acc) {
    MocapFilterState& s = state_;
    if (params_.rest_bias && s.ts_s > 0.0) {
        low_pass(s.rest_acc_lp, acc.data(), rest_lp_, params_.rest_filter_tau_s, s.ts_s);
        const double th = params_.rest_th_acc_m_s2;
        if ((acc - out3(s.rest_acc_lp)).squaredNorm() >= th * th) {
            s.rest_time_s = 0.0;
            s.rest_detected = false;
        } else {
            s.rest_time_s += s.ts_s;
            if (s.rest_time_s >= params_.rest_min_time_s) s.rest_detected = true;
        }
    }
    // Low-pass in the almost-inertial frame: while the sensor turns, linear acceleration
    // averages out there, gravity does not.
    math::Vec3 acc_i = math::rotate(s.q_i_sensor, acc);
    clip_acc_deviation(acc_i);
    low_pass(s.acc_lp, acc_i.data(), acc_lp_, s.tau_acc_eff_s, s.ts_s);
    const math::Vec3 acc_e = math::rotate(s.q_e6_i, out3(s.acc_lp)).normalized();

    // Rotate the filtered vector onto the vertical (inclination only, no heading change).
    s.q_e6_i = (tilt_to_vertical(acc_e) * s.q_e6_i).normalized();

    if (s.ts_s > 0.0 && (params_.rest_bias || params_.motion_bias)) update_bias(acc_e);
}

// Linear acceleration (header): the low-pass averages linear acceleration that comes and goes,
// but a push that keeps one direction for a second moves it as if gravity had tilted, and the
// motion bias measurement then takes the correction for gyro bias. Such a push stands out
// from the deviations the motion usually makes: the deviation of the specific force from the
// low-passed gravity is clipped (a Huber weight) at a few running medians of that deviation.
// A running median, not a mean square, so the pushes themselves hardly raise it; moved by a
// bounded factor per second, so it follows a change of motion within seconds (vigorous
// motion raises it and is then averaged as before). acc_clip is the share let through.
void MocapFilter::clip_acc_deviation(math::Vec3& acc_i) {
    MocapFilterState& s = state_;
    s.acc_clip = 1.0;
    if (s.acc_lp.count == 0 || s.ts_s == 0.0) return;
    const math::Vec3 lp = out3(s.acc_lp);
    const math::Vec3 dev = acc_i - lp;
    const double d = dev.norm();
    if (s.acc_dev_median_m_s2 == 0.0) s.acc_dev_median_m_s2 = std::max(d, kAccDevMedianMinM_s2);
    const double th = std::max(kAccClipMinM_s2, kAccClipScales * s.acc_dev_median_m_s2);
    if (d > th && s.acc_lp.running) {
        s.acc_clip = th / d;
        acc_i = lp + s.acc_clip * dev;
        ++s.acc_samples_clipped;
    }
    s.acc_dev_median_m_s2 = d > s.acc_dev_median_m_s2 ? s.acc_dev_median_m_s2 * acc_dev_median_step_
                                                      : s.acc_dev_median_m_s2 / acc_dev_median_step_;
    s.acc_dev_median_m_s2 = std::max(s.acc_dev_median_m_s2, kAccDevMedianMinM_s2);
}

void MocapFilter::update_bias(const math::Vec3& acc_e) {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    const double clip = p.bias_clip_deg_s * kDeg;

    // R maps sensor to the 6D earth frame. R and R·bias are low-passed like the
    // accelerometer so the motion measurement compares quantities with the same delay.
    const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> r = (s.q_e6_i * s.q_i_sensor).toRotationMatrix();
    const double rb[2] = {r.row(0).dot(s.bias_rad_s), r.row(1).dot(s.bias_rad_s)};
    low_pass(s.bias_r_lp, r.data(), acc_lp_, s.tau_acc_eff_s, s.ts_s);
    low_pass(s.bias_b_lp, rb, acc_lp_, s.tau_acc_eff_s, s.ts_s);
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> r_lp(s.bias_r_lp.out.data());

    // Prediction: the bias may wander, so its uncertainty grows back slowly.
    for (int i = 0; i < 3; ++i) {
        if (s.bias_p(i, i) < bias_p0_) s.bias_p(i, i) += bias_v_;
    }
    if (s.vertical_bias_var < vertical_bias_var0_) s.vertical_bias_var += bias_v_;

    math::Vec3 e;
    math::Mat3 h;
    math::Vec3 w;
    if (s.rest_detected && p.rest_bias) {
        e = out3(s.rest_gyro_lp) - s.bias_rad_s;
        h = math::Mat3::Identity();
        w = math::Vec3::Constant(bias_rest_w_);
        s.vertical_bias_var = 1.0 / (1.0 / s.vertical_bias_var + 1.0 / bias_rest_w_);
    } else if (p.motion_bias && s.bias_r_lp.running) {
        // The accelerometer's correction this step is the rotation vector (acc_e.y, -acc_e.x)
        // in earth axes; in steady state it cancels R·(bias error)·ts. While the low-passes
        // still average their first tau_acc_s, the corrections are the start-up alignment
        // instead, so the measurement waits for them.
        h = r_lp;
        e.x() = -acc_e.y() / s.ts_s + s.bias_b_lp.out[0] - h.row(0).dot(s.bias_rad_s);
        e.y() = acc_e.x() / s.ts_s + s.bias_b_lp.out[1] - h.row(1).dot(s.bias_rad_s);
        e.z() = -h.row(2).dot(s.bias_rad_s);
        // A clipped sample's correction is partly linear acceleration: its variance grows with
        // the square of the deviation over the clip.
        w = math::Vec3(bias_motion_w_, bias_motion_w_, bias_vertical_w_) / (s.acc_clip * s.acc_clip);
    } else {
        return;
    }
    e = e.cwiseMax(-clip).cwiseMin(clip);
    const math::Mat3 ph = s.bias_p * h.transpose();
    const math::Mat3 k = ph * (math::Mat3(w.asDiagonal()) + h * ph).inverse();
    s.bias_rad_s += k * e;
    s.bias_p -= k * h * s.bias_p;
    s.bias_rad_s = s.bias_rad_s.cwiseMax(-clip).cwiseMin(clip);
}

void MocapFilter::update_mag_guard(const math::Vec3& mag_e) {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    low_pass(s.mag_lp, mag_e.data(), mag_current_lp_, p.mag_current_tau_s, s.ts_s);
    if (s.ts_s == 0.0) return;  // timers need the sample period
    const math::Vec3 m = out3(s.mag_lp);
    ++s.mag_stat_count;
    const double k_noise = std::max(k_mag_noise_, 1.0 / static_cast<double>(s.mag_stat_count));
    s.mag_noise_var += k_noise * ((mag_e - m).squaredNorm() / 3.0 - s.mag_noise_var);
    s.mag_norm = m.norm();
    if (s.mag_norm <= 0.0) return;
    s.mag_dip_rad = -std::asin(std::clamp(m.z() / s.mag_norm, -1.0, 1.0));

    // Thresholds: the configured ones, widened when the sensor's own noise (after the
    // low-pass, variance ratio 0.5·ts/tau for this Butterworth) would cross them. When the
    // noise needs more than twice the configured width, no disturbance of the configured
    // size can be told from noise: the guard stands aside (mag_guard_blind) rather than
    // rejecting at random.
    const double var_ratio = p.mag_current_tau_s > 0.0 ? std::min(1.0, 0.5 * s.ts_s / p.mag_current_tau_s) : 1.0;
    const double noise = p.mag_noise_margin * std::sqrt(s.mag_noise_var * var_ratio);
    const double norm_for_blind = s.mag_ref_norm > 0.0 ? s.mag_ref_norm : s.mag_norm;
    s.mag_guard_blind = noise > 2.0 * p.mag_norm_th * norm_for_blind;
    const auto agrees = [&](double ref_norm, double ref_dip) {
        const double norm_th = std::max(p.mag_norm_th * ref_norm, noise);
        const double dip_th = std::max(p.mag_dip_th_deg * kDeg, noise / s.mag_norm);
        return std::abs(s.mag_norm - ref_norm) < norm_th && std::abs(s.mag_dip_rad - ref_dip) < dip_th;
    };
    if (s.mag_guard_blind) {
        if (s.mag_ref_norm == 0.0) {  // keep a reference for when the noise drops
            s.mag_ref_norm = s.mag_norm;
            s.mag_ref_dip_rad = s.mag_dip_rad;
            ++s.mag_fields_accepted;
        }
        s.mag_disturbed = false;
        s.mag_heading_disturbed = false;
        s.mag_undisturbed_time_s = 0.0;
        return;
    }

    if (s.mag_ref_norm > 0.0 && agrees(s.mag_ref_norm, s.mag_ref_dip_rad)) {
        s.mag_undisturbed_time_s += s.ts_s;
        if (s.mag_undisturbed_time_s >= p.mag_min_undisturbed_time_s) {
            s.mag_disturbed = false;
            s.mag_ref_norm += k_mag_ref_ * (s.mag_norm - s.mag_ref_norm);
            s.mag_ref_dip_rad += k_mag_ref_ * (s.mag_dip_rad - s.mag_ref_dip_rad);
            // How much an accepted field departs from its reference in norm and dip, low-passed:
            // a field that varies from place to place (or a residual of the sensor's calibration)
            // varies in heading by about as much, per axis (update_heading_bias).
            const double dn = s.mag_norm - s.mag_ref_norm;
            const double dd = s.mag_norm * (s.mag_dip_rad - s.mag_ref_dip_rad);
            s.mag_dev_norm_ut += k_field_dev_ * (dn - s.mag_dev_norm_ut);
            s.mag_dev_dip_ut += k_field_dev_ * (dd - s.mag_dev_dip_ut);
            const double v = 0.5 * (s.mag_dev_norm_ut * s.mag_dev_norm_ut + s.mag_dev_dip_ut * s.mag_dev_dip_ut);
            s.mag_var_ut2 += k_mag_ref_ * (v - s.mag_var_ut2);
        }
    } else {
        if (!mag_rejected() && s.mag_ref_norm > 0.0) ++s.mag_disturbances;
        s.mag_undisturbed_time_s = 0.0;
        s.mag_disturbed = true;
    }

    // A new field that stays self-consistent replaces the reference: after
    // mag_new_time_s of motion (a still sensor beside a magnet is also consistent), or
    // for the very first field after mag_new_first_time_s.
    if (s.mag_candidate_norm > 0.0 && agrees(s.mag_candidate_norm, s.mag_candidate_dip_rad)) {
        const bool first = s.mag_ref_norm == 0.0;
        if (first || out3(s.rest_gyro_lp).norm() >= p.mag_new_min_gyro_deg_s * kDeg) {
            s.mag_candidate_time_s += s.ts_s;
        }
        s.mag_candidate_norm += k_mag_ref_ * (s.mag_norm - s.mag_candidate_norm);
        s.mag_candidate_dip_rad += k_mag_ref_ * (s.mag_dip_rad - s.mag_candidate_dip_rad);
        const double need = first ? p.mag_new_first_time_s : p.mag_new_time_s;
        if (mag_rejected() && s.mag_candidate_time_s >= need) accept_candidate_field();
    } else {
        s.mag_candidate_time_s = 0.0;
        s.mag_candidate_norm = s.mag_norm;
        s.mag_candidate_dip_rad = s.mag_dip_rad;
    }
}

void MocapFilter::accept_candidate_field() {
    MocapFilterState& s = state_;
    s.mag_ref_norm = s.mag_candidate_norm;
    s.mag_ref_dip_rad = s.mag_candidate_dip_rad;
    s.mag_disturbed = false;
    s.mag_heading_disturbed = false;
    // The new field may point elsewhere: the disagreement test follows the heading converging to it.
    s.mag_dis_drift_rad = s.mag_dis_lp_rad;
    s.mag_undisturbed_time_s = params_.mag_min_undisturbed_time_s;
    ++s.mag_fields_accepted;
}

// A disturbance that turns the horizontal field with little change of norm and dip shows up
// only as heading disagreement between magnetometer and gyro-propagated estimate. In
// normal operation that disagreement is gyro drift over ~tau_mag_s plus noise; its low-pass
// leaving that band (threshold widened to mag_noise_margin standard deviations of the
// low-passed noise) marks the field as disturbed until it comes back within half.
void MocapFilter::update_heading_guard() {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    if (p.mag_heading_th_deg <= 0.0 || s.ts_s == 0.0 || s.mag_stat_count == 0) return;
    const double d = math::wrap_pi(s.last_mag_disagreement_rad - s.mag_dis_lp_rad);
    s.mag_dis_lp_rad = math::wrap_pi(s.mag_dis_lp_rad + k_dis_ * d);
    const double k_noise = std::max(k_mag_noise_, 1.0 / static_cast<double>(s.mag_stat_count));
    s.mag_dis_var += k_noise * (d * d - s.mag_dis_var);
    const double lp_sigma = std::sqrt(s.mag_dis_var * 0.5 * s.ts_s / p.mag_heading_tau_s);
    const double th_cfg = p.mag_heading_th_deg * kDeg;
    const double th = std::max(th_cfg, p.mag_noise_margin * lp_sigma);
    if (s.mag_guard_blind || th > 2.0 * th_cfg || s.k_mag_init != 0.0) {
        // Noise hides a disturbance of that size, or the heading still converges from the first readings.
        s.mag_heading_disturbed = false;
        s.mag_dis_drift_rad = s.mag_dis_lp_rad;
        return;
    }
    // A disturbance is a jump of the disagreement. mag_dis_drift_rad follows it as far as the
    // heading correction (which pulls it towards zero at 1 / tau_mag_s while the field is used)
    // and a drift of the vertical bias within kDriftSigmas of what the rest measurements leave
    // unknown can move it, and holds it while the field is flagged: a disagreement that grows
    // steadily is an unlearned bias (update_heading_bias learns it meanwhile), and the heading
    // converging to a newly accepted field is followed; a jump away from it is a disturbance,
    // which ends when the disagreement is back near the level held. With the bias known from
    // rest, nothing moves but the correction's pull: the test of the level it always was.
    const double jump = math::wrap_pi(s.mag_dis_lp_rad - s.mag_dis_drift_rad);
    if (!s.mag_heading_disturbed && std::abs(jump) > th) {
        if (!mag_rejected()) ++s.mag_disturbances;
        s.mag_heading_disturbed = true;
        s.mag_candidate_time_s = 0.0;  // a new field must prove itself from now on
    } else if (s.mag_heading_disturbed && std::abs(jump) < 0.5 * th) {
        s.mag_heading_disturbed = false;
    }
    if (s.mag_heading_disturbed) return;
    const double drift = kDriftSigmas * std::sqrt(s.vertical_bias_var) * 0.01 * kDeg;
    const bool used = !mag_rejected() || s.mag_reject_time_s > p.mag_max_rejection_time_s;
    const double pull = used ? s.mag_dis_drift_rad / s.tau_mag_eff_s : 0.0;
    s.mag_dis_drift_rad =
        math::wrap_pi(s.mag_dis_drift_rad + std::clamp(jump, (-drift - pull) * s.ts_s, (drift - pull) * s.ts_s));
}

// Vertical gyro bias from the heading corrections. The accelerometer's corrections measure the
// bias about the horizontal axes only; about the vertical, an unlearned bias turns the 6D frame
// at r = (R·(b − b̂))_z, the field seen in it turns at −r, and a first-order heading correction
// (gain k per sample) lags it by r·tau_mag_s for good: a constant disagreement that the heading
// guard took for a disturbance. A loop like the heading correction's, run on the field while it
// is trusted and restarted at each rejection (so a disturbance it did not see is not in it),
// makes the same measurement as the accelerometer's corrections: its correction rate
// c = k·d / ts obeys c_n = (1 − k)·c_{n−1} − k·r_n, so with m and n the same low-pass (started
// at zero with the loop) of R's vertical row and of (R·b̂)_z, c = n − m·b exactly, and
// e = n − c − m·b̂ = m·(b − b̂) is a Kalman measurement of the bias with the row m.
void MocapFilter::update_heading_bias(const math::Vec3& h, const math::Mat3& r_e6_s, bool trusted) {
    MocapFilterState& s = state_;
    const double k = k_mag_;
    if (!trusted || s.ts_s == 0.0 || k <= 0.0 || h.squaredNorm() == 0.0) {
        s.hb_running = false;
        return;
    }
    const math::Vec3 r_z = r_e6_s.row(2).transpose();
    if (!s.hb_running || s.hb_k != k) {
        s.hb_running = true;
        s.hb_k = k;
        s.hb_delta_rad = std::atan2(h.x(), h.y());
        s.hb_r_lp.setZero();
        s.hb_rb_lp = 0.0;
        return;
    }
    s.hb_r_lp += k * (r_z - s.hb_r_lp);
    s.hb_rb_lp += k * (r_z.dot(s.bias_rad_s) - s.hb_rb_lp);
    const double d = math::wrap_pi(std::atan2(h.x(), h.y()) - s.hb_delta_rad);
    s.hb_delta_rad = math::wrap_pi(s.hb_delta_rad + k * d);
    const double clip = params_.bias_clip_deg_s * kDeg;
    const double e = std::clamp(s.hb_rb_lp - k * d / s.ts_s - s.hb_r_lp.dot(s.bias_rad_s), -clip, clip);
    // The field's own heading error (σ_ψ, from how much its norm and dip vary, update_mag_guard)
    // moves this loop's correction rate by about σ_ψ / tau_mag_s for about tau_mag_s: one
    // independent value per tau_mag_s, a variance of 2·σ_ψ² / (tau_mag_s·ts) per sample. In a
    // clean field the measurement weighs what the accelerometer's corrections weigh
    // (bias_sigma_motion_deg_s); where the field varies from place to place, far less.
    const double h2 = h.squaredNorm();
    const double var_psi = s.mag_var_ut2 / h2;
    const double w = bias_motion_w_ + 2.0 * var_psi / (s.tau_mag_eff_s * s.ts_s) * kRadS2ToBiasUnits;
    const math::Vec3 ph = s.bias_p * s.hb_r_lp;
    const math::Vec3 gain = ph / (s.hb_r_lp.dot(ph) + w);
    s.bias_rad_s += gain * e;
    s.bias_p -= gain * ph.transpose();
    s.bias_rad_s = s.bias_rad_s.cwiseMax(-clip).cwiseMin(clip);
    ++s.heading_bias_samples;
}

// A magnet carried by the sensor adds a constant offset b to every reading in the sensor
// frame: in the 6D earth frame the field becomes m_e = c + R b (R: sensor -> 6D earth, c the
// earth field), a field that no longer turns with the gyro. Exponentially weighted least
// squares over mag_offset_tau_s with regressor [I, R] has normal equations that need only
// n = Σ1, S = ΣR, Σm_e and Σm_s (because Rᵀ m_e = m_s and RᵀR = I):
//   (n² I − SᵀS) b = n Σm_s − Sᵀ Σm_e.
// n² I − SᵀS measures how much the sensor turned in the window: zero at rest (b is then
// unobservable), about n² when its attitudes are spread evenly. A ridge of
// mag_offset_ridge·n² shrinks the components the motion does not reveal towards zero. The
// offset is subtracted in full from 2·mag_offset_min of the field norm, not below
// mag_offset_min (what a calibrated sensor leaves), linearly in between, so it comes and goes
// without a step in the field.
void MocapFilter::update_mag_offset(const math::Vec3& mag_s, const math::Mat3& r_e_s) {
    MocapFilterState& s = state_;
    // At rest the samples say nothing about b and would only make the window forget it.
    if (s.rest_detected) return;
    const double l = 1.0 - k_mag_offset_;
    s.mag_off_n = l * s.mag_off_n + 1.0;
    s.mag_off_r = l * s.mag_off_r + r_e_s;
    s.mag_off_sum_e = l * s.mag_off_sum_e + r_e_s * mag_s;
    s.mag_off_sum_s = l * s.mag_off_sum_s + mag_s;
    const double n2 = s.mag_off_n * s.mag_off_n;
    const math::Mat3 g =
        (1.0 + params_.mag_offset_ridge) * n2 * math::Mat3::Identity() - s.mag_off_r.transpose() * s.mag_off_r;
    const math::Vec3 rhs = s.mag_off_n * s.mag_off_sum_s - s.mag_off_r.transpose() * s.mag_off_sum_e;
    s.mag_offset_ut = g.inverse() * rhs;
    const double norm = s.mag_ref_norm > 0.0 ? s.mag_ref_norm : s.mag_off_sum_s.norm() / s.mag_off_n;
    const double rel = norm > 0.0 ? s.mag_offset_ut.norm() / norm : 0.0;
    // A field too noisy for the guard is too noisy for this estimate as well.
    s.mag_offset_weight = s.mag_guard_blind ? 0.0 : std::clamp(rel / params_.mag_offset_min - 1.0, 0.0, 1.0);
}

// Magnetometer lag (header, "Magnetometer lag"): a reading d late has turned by ω·d less than
// the sensor, which the heading correction takes for an error while the sensor turns. The
// reading is predicted d ahead from the rate, so the lag costs no latency. d is learned on
// the part of the field that turns with the sensor (the offset fixed to it taken out), from
// samples whose field the guard accepts, and nothing is taken out before the estimate has
// converged.
math::Vec3 MocapFilter::take_out_mag_delay(const math::Vec3& mag, const math::Vec3& rate, double dt_s) {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    if (p.mag_delay_s < 0.0) {
        const bool usable = !p.mag_guard || !(mag_rejected() || s.mag_guard_blind);
        s.mag_delay.update(rate, mag, true, dt_s, usable, mag_delay_forgetting_);
    }
    s.mag_delay_s = p.mag_delay_s < 0.0 ? p.mag_delay_share * s.mag_delay.delay_s(kMagDelayMaxS) : p.mag_delay_s;
    return s.mag_delay_s > 0.0 ? mag_ahead(mag, rate, s.mag_delay_s) : mag;
}

void MocapFilter::update_mag(const math::Vec3& mag_raw, const math::Vec3& rate, double dt_s) {
    MocapFilterState& s = state_;
    const MocapFilterParams& p = params_;
    const math::Quat q6 = s.q_e6_i * s.q_i_sensor;
    math::Vec3 mag = mag_raw;
    if (k_mag_offset_ > 0.0) {
        update_mag_offset(mag_raw, q6.toRotationMatrix());
        mag -= s.mag_offset_weight * s.mag_offset_ut;
    }
    mag = take_out_mag_delay(mag, rate, dt_s);
    const math::Vec3 mag_e = math::rotate(q6, mag);
    if (p.mag_guard) update_mag_guard(mag_e);

    const math::Vec3 h(mag_e.x(), mag_e.y(), 0.0);
    // The field's own heading in the 6D frame (heading_split().field_heading_rad), whether or
    // not the heading correction uses it: its direction, low-passed over mag_heading_tau_s.
    if (const double hn = h.norm(); hn > 0.0) {
        const double k = s.field_dir_lp.squaredNorm() == 0.0 ? 1.0 : k_dis_;
        s.field_dir_lp += k * (h / hn - s.field_dir_lp);
    }
    s.last_mag_disagreement_rad = heading_disagreement(h, s.delta_rad, s.mag_horizontal_lp.norm());
    if (p.mag_guard) update_heading_guard();
    double k = k_mag_;
    if (p.mag_guard && s.ts_s > 0.0) {
        if (mag_rejected()) {
            if (s.mag_reject_time_s <= p.mag_max_rejection_time_s) {
                s.mag_reject_time_s += s.ts_s;
                k = 0.0;
            } else {
                k /= p.mag_rejection_factor;
            }
        } else {
            s.mag_reject_time_s = std::max(s.mag_reject_time_s - p.mag_rejection_factor * s.ts_s, 0.0);
        }
    }
    // After a rejection the heading the gyro held meanwhile comes back to the field at
    // 1 / tau_mag_s: it is the field's again (heading_split().mag_trusted) once the
    // disagreement is within the guard's threshold.
    if (p.mag_guard && mag_rejected()) {
        s.mag_settled = false;
    } else if (std::abs(s.mag_dis_lp_rad) < p.mag_heading_th_deg * kDeg) {
        s.mag_settled = true;
    }
    if (p.motion_bias) {
        const bool trusted = k == k_mag_ && !(p.mag_guard && (s.mag_guard_blind || s.mag_ref_norm == 0.0));
        update_heading_bias(h, q6.toRotationMatrix(), trusted);
    }
    // Fast start: for the N-th reading the heading is that of the vector mean of the first
    // N horizontal fields, until 1/N falls below the steady-state gain.
    if (s.k_mag_init != 0.0) {
        s.mag_horizontal_lp += s.k_mag_init * (h - s.mag_horizontal_lp);
        if (s.mag_horizontal_lp.squaredNorm() > 0.0) {
            s.delta_rad = std::atan2(s.mag_horizontal_lp.x(), s.mag_horizontal_lp.y());
        }
        s.k_mag_init = s.k_mag_init / (s.k_mag_init + 1.0);
        if (s.ts_s > 0.0 && s.k_mag_init * s.tau_mag_eff_s < s.ts_s) s.k_mag_init = 0.0;
        return;
    }
    if (k == 0.0) {
        ++s.mag_samples_rejected;
        return;
    }
    s.mag_horizontal_lp += k_mag_ * (h - s.mag_horizontal_lp);
    s.delta_rad = math::wrap_pi(s.delta_rad + k * s.last_mag_disagreement_rad);
}

FilterDiagnostics MocapFilter::diagnostics() const {
    FilterDiagnostics d;
    d.rest = state_.rest_detected;
    d.mag_field_disturbed = params_.mag_guard && state_.mag_disturbed;
    d.mag_heading_disturbed = params_.mag_guard && state_.mag_heading_disturbed;
    d.mag_rejected = params_.mag_guard && mag_rejected();
    d.mag_offset_weight = state_.mag_offset_weight;
    d.mag_offset_ut = state_.mag_offset_ut;
    return d;
}

HeadingSplit MocapFilter::heading_split() const {
    HeadingSplit h;
    h.q6 = orientation_6d();
    h.mag_heading_rad = state_.delta_rad;
    h.has_mag_heading = state_.samples > state_.no_mag_samples;
    h.mag_trusted = h.has_mag_heading && !(params_.mag_guard && mag_rejected()) && state_.mag_settled;
    h.field_norm_ut = state_.mag_norm;
    h.field_heading_rad = state_.field_dir_lp.squaredNorm() > 0.0
                              ? std::atan2(state_.field_dir_lp.x(), state_.field_dir_lp.y())
                              : state_.delta_rad;
    h.field_usable =
        h.has_mag_heading &&
        !(params_.mag_guard && (state_.mag_disturbed || state_.mag_guard_blind || state_.mag_ref_norm == 0.0));
    h.field_dip_rad = state_.mag_dip_rad;
    h.frame_epoch = state_.attitude_restarts;
    return h;
}

math::Quat MocapFilter::orientation_6d() const {
    return (state_.q_e6_i * state_.q_i_sensor).normalized();
}

math::Quat MocapFilter::orientation() const {
    const math::Quat rz(std::cos(0.5 * state_.delta_rad), 0.0, 0.0, std::sin(0.5 * state_.delta_rad));
    return (rz * orientation_6d()).normalized();
}

}  // namespace mocap::filter
