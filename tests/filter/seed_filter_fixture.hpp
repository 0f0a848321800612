// seed_filter_fixture.hpp — helpers shared by the CSMO and particle-filter tests: run a
// filter over a simulated recording and score it with the error metrics of docs/design.md, "Error metrics",, and a
// small inline motion (constant body rate, gravity and field rotated by the truth).
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "filter/attitude_solver.hpp"
#include "filter/orientation_filter.hpp"
#include "sim/scenario.hpp"

namespace mocap::filter::testing {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

struct Rmse {
    double total_deg = 0, heading_deg = 0, inclination_deg = 0;
    double roll_deg = 0, pitch_deg = 0, yaw_deg = 0;
    double worst_deg = 0;        ///< largest total error over the evaluated samples
    double last_above_10_s = 0;  ///< last time the total error exceeded 10° (any sample)
    int samples = 0;
};

/// Runs `f` over every row, scores the rows from skip_s on.
inline Rmse run(OrientationFilter& f, const std::vector<sim::ScenarioRow>& rows, double skip_s) {
    double st = 0, sh = 0, si = 0, sr = 0, sp = 0, sy = 0;
    Rmse r;
    for (const sim::ScenarioRow& row : rows) {
        f.update(row.sample);
        const double t = static_cast<double>(row.sample.t_us) * 1e-6;
        const math::Quat q = f.orientation();
        const math::Quat e = q * row.q_earth_sensor.conjugate();
        const double tot = math::error_total_rad(e) * kRadToDeg;
        if (tot > 10.0) r.last_above_10_s = t;
        if (t < skip_s) continue;
        const math::EulerZyx a = math::to_euler_zyx(q), b = math::to_euler_zyx(row.q_earth_sensor);
        st += tot * tot;
        sh += std::pow(math::error_heading_rad(e) * kRadToDeg, 2);
        si += std::pow(math::error_inclination_rad(e) * kRadToDeg, 2);
        sr += std::pow(math::wrap_pi(a.roll_rad - b.roll_rad) * kRadToDeg, 2);
        sp += std::pow(math::wrap_pi(a.pitch_rad - b.pitch_rad) * kRadToDeg, 2);
        sy += std::pow(math::wrap_pi(a.yaw_rad - b.yaw_rad) * kRadToDeg, 2);
        r.worst_deg = std::max(r.worst_deg, tot);
        ++r.samples;
    }
    const double n = r.samples > 0 ? r.samples : 1;
    r.total_deg = std::sqrt(st / n);
    r.heading_deg = std::sqrt(sh / n);
    r.inclination_deg = std::sqrt(si / n);
    r.roll_deg = std::sqrt(sr / n);
    r.pitch_deg = std::sqrt(sp / n);
    r.yaw_deg = std::sqrt(sy / n);
    return r;
}

/// Noiseless rotation from q0 at rate_hz for duration_s with body rate w_rad_s(t); dip 60°.
template <class Rate>
std::vector<sim::ScenarioRow> rotating(const math::Quat& q0, Rate w_rad_s, double rate_hz, double duration_s) {
    std::vector<sim::ScenarioRow> rows;
    const double dt = 1.0 / rate_hz;
    const math::Vec3 g(0, 0, 9.81), h = 48.0 * field_direction_enu(60.0 * std::numbers::pi / 180.0);
    math::Quat q = q0;
    const int n = static_cast<int>(duration_s * rate_hz);
    for (int k = 0; k <= n; ++k) {
        const math::Vec3 w = w_rad_s(k * dt);
        if (k > 0) q = (q * math::quat_from_rotvec(w * dt)).normalized();
        sim::ScenarioRow r;
        r.sample.t_us = static_cast<std::int64_t>(std::llround(k * dt * 1e6));
        r.sample.gyro_rad_s = math::to_array(w);
        r.sample.accel_m_s2 = math::to_array(math::rotate(q.conjugate(), g));
        r.sample.mag_ut = math::to_array(math::rotate(q.conjugate(), h));
        r.q_earth_sensor = q;
        r.moving = true;
        r.gyro_true_rad_s = w;
        r.lin_acc_earth_m_s2 = math::Vec3::Zero();
        r.mag_earth_ut = h;
        rows.push_back(r);
    }
    return rows;
}

/// Noiseless constant body rate from q0 at rate_hz for duration_s; dip 60°.
inline std::vector<sim::ScenarioRow> constant_rate(const math::Quat& q0, const math::Vec3& w_rad_s, double rate_hz,
                                                   double duration_s) {
    return rotating(
        q0, [&w_rad_s](double) { return w_rad_s; }, rate_hz, duration_s);
}

/// 100 Hz samples of a sensor swaying about every axis while it turns about the vertical at
/// 1 rad/s on average (a lag shows where the rate changes, and the steady turn makes a late
/// field a steady heading error), from a 1 kHz noiseless truth: each gyro
/// reading is the mean rate over the 10 ms it covers, each field reading is the field
/// lag_ms earlier, as a magnetometer with a lag reports it.
inline std::vector<sim::ScenarioRow> turning_with_late_field(int lag_ms, double duration_s) {
    const auto fine = rotating(
        math::from_euler_zyx({0.0, 0.2, 0.1}),
        [](double t) {
            return math::Vec3(0.3 * std::sin(2.0 * t), 0.2 * std::cos(3.0 * t), 1.0 + 1.5 * std::sin(4.0 * t));
        },
        1000.0, duration_s);
    std::vector<sim::ScenarioRow> rows;
    for (std::size_t i = 50; i < fine.size(); i += 10) {
        sim::ScenarioRow r = fine[i];
        math::Vec3 w = math::Vec3::Zero();
        for (std::size_t k = i - 9; k <= i; ++k)
            w += fine[k].gyro_true_rad_s / 10.0;
        r.sample.gyro_rad_s = math::to_array(w);
        r.sample.mag_ut = fine[i - static_cast<std::size_t>(lag_ms)].sample.mag_ut;
        rows.push_back(r);
    }
    return rows;
}

/// The fourati scenario's truth starts at the paper's q(0) = identity in NED, which is
/// q_enu_ned() here; the paper's far-off initial estimate maps the same way.
inline math::Quat fourati_start_truth() {
    return math::q_enu_ned();
}
inline math::Quat fourati_paper_initial_estimate() {
    return math::q_enu_ned() * math::Quat(0.2, 0.5, 0.7, 0.3).normalized();
}

}  // namespace mocap::filter::testing
