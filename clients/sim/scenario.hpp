// scenario.hpp — benchmark recordings of one sensor with their true orientation.
//
// Five scenarios (docs/accuracy.md describes them and how the paper's NED model maps here):
//   fourati    Fourati et al.'s CSMO simulation: 60 s at 100 Hz, the body rate of the paper's
//              Table I (fourati_table_rate_rad_s) from the paper's q(0) = identity (NED), white
//              noise σ = 0.4 on gyro (rad/s), accelerometer (m/s²) and magnetometer (G, i.e.
//              40 µT here) on a 0.5 G field at 60° inclination, no linear acceleration, no
//              gyro bias.
//   realistic  MEMS-grade (MPU9250-like) noise, a constant gyro bias, human-like motion with
//              rest periods and bursts of linear acceleration; 90 s at 100 Hz.
//   magnetic   realistic plus a bounded magnetic disturbance near the middle (a steel object:
//              the horizontal field turns by 39° and its norm and dip change a little).
//   continuous fourati's motion (up to 2.5 rad/s, never at rest) with realistic's sensor noise
//              and field and a constant gyro bias of 0.02 rad/s (1.15 °/s) on every axis
//              (signs from the seed): bias that can only be learned in motion.
//   bursts     continuous with signs that differ between the axes (never all equal) and eight
//              1 s bursts of linear acceleration (2–5 m/s², a random earth-frame direction each,
//              raised-cosine ramps, one in each eighth of the recording): bias learned in motion
//              while the accelerometer is, at times, not measuring gravity.
//
// Conventions (docs/design.md, "Quaternions and frames"): earth frame ENU, q_earth_sensor
// rotates sensor vectors into the earth frame, (w, x, y, z) Hamilton. The accelerometer reads
// real specific force f = R(q)ᵀ (a_lin + [0, 0, 9.81]) (+9.81 on the up axis at rest), not the
// paper's sign.
//
// Discretisation: row k's gyro reading (without bias and noise) is the constant body rate
// that carries truth k-1 to truth k over dt: q_k = q_{k-1} ⊗ exp(ω_k dt / 2). A filter that
// propagates with the current sample's rate therefore reproduces the truth exactly on
// noiseless data. Row 0 is at t = 0. Table I's truth is the integral of its continuous rate
// (RK4, 8 steps per sample, piece by piece), so the readings are that rate averaged over
// each interval.
//
// Deterministic: the same (kind, seed, options) gives bit-identical rows with any standard
// library (SimRng shapes its own distributions). Thread-safety: pure functions.
// Cost: make_scenario allocates the whole recording (~9000 rows, < 10 ms).
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"

namespace mocap::sim {

using math::Quat;
using math::Vec3;

enum class ScenarioKind { fourati, realistic, magnetic, continuous, bursts };

/// "fourati" | "realistic" | "magnetic" | "continuous" | "bursts" -> kind; nullopt for anything else.
std::optional<ScenarioKind> parse_scenario_kind(std::string_view name);
std::string_view scenario_name(ScenarioKind kind);

/// Fixed characteristics of a scenario (the same for every seed).
struct ScenarioSpec {
    double rate_hz = 100.0;
    double duration_s = 60.0;
    double gyro_noise_rad_s = 0.0;         ///< σ of white gyro noise per sample
    double accel_noise_m_s2 = 0.0;         ///< σ of white accelerometer noise per sample
    double mag_noise_ut = 0.0;             ///< σ of white magnetometer noise per sample
    double gyro_bias_max_rad_s = 0.0;      ///< largest per-axis bias magnitude
    double gyro_bias_min_fraction = 0.25;  ///< per-axis magnitude drawn in [fraction·max, max],
                                           ///< random sign
    bool gyro_bias_mixed_signs = false;    ///< the axes' signs are never all equal
    int lin_acc_bursts = 0;                ///< bursts of linear acceleration on Table I's motion,
                                           ///< one in each equal slice of the recording
    double lin_acc_burst_s = 0.0;          ///< length of each burst, ramps included, s
    double lin_acc_burst_ramp_s = 0.0;     ///< raised-cosine ramp at each end of a burst, s
    double lin_acc_burst_min_m_s2 = 0.0;   ///< a burst's plateau magnitude is drawn in [min, max]
    double lin_acc_burst_max_m_s2 = 0.0;
    Vec3 gravity_up_m_s2{0.0, 0.0, 9.81};  ///< specific force at rest, earth frame (ENU)
    Vec3 mag_field_ut = Vec3::Zero();      ///< undisturbed earth field, ENU, µT
};

ScenarioSpec scenario_spec(ScenarioKind kind);

/// Fourati et al.'s Table I: body rate (rad/s, sensor frame) of piece 1..4 (0–15, 15–30,
/// 30–45, 45–60 s) at the absolute time t_s. Pieces 1 and 3 are the same; piece 4 is written
/// as printed, −1.5 sin(−1.5 t) on x. Defined for any t, so a piece can be evaluated on its
/// boundary.
Vec3 fourati_table_rate_rad_s(int piece, double t_s);

/// Knobs for tests and studies; the defaults are the benchmark.
struct ScenarioOptions {
    double noise_scale = 1.0;      ///< multiplies every noise σ (0 = noiseless sensors)
    double mag_noise_scale = 1.0;  ///< multiplies the magnetometer σ once more (studies of
                                   ///< how much heading the field noise costs)
    bool gyro_bias = true;         ///< false: no gyro bias even where the scenario has one
};

/// One sample and the truth behind it.
struct ScenarioRow {
    ImuSample sample;         ///< what the sensor reports (t_us, gyro, accel, mag)
    Quat q_earth_sensor;      ///< true orientation, ENU, unit norm
    bool moving = false;      ///< the subject moves (BROAD's `movement` column)
    Vec3 gyro_true_rad_s;     ///< true body rate over (t_{k-1}, t_k], no bias, no noise
    Vec3 lin_acc_earth_m_s2;  ///< true linear acceleration, earth frame
    Vec3 mag_earth_ut;        ///< true field at the sensor, earth frame (with disturbance)
};

struct Scenario {
    ScenarioKind kind = ScenarioKind::fourati;
    std::uint64_t seed = 0;
    ScenarioSpec spec;
    Vec3 gyro_bias_rad_s = Vec3::Zero();  ///< constant bias added to every gyro reading
    std::vector<ScenarioRow> rows;
};

/// Generates the whole recording.
Scenario make_scenario(ScenarioKind kind, std::uint64_t seed, const ScenarioOptions& options = {});

}  // namespace mocap::sim
