// particle_filter.hpp — regularised quaternion particle filter with gyro-bias state
// (Li et al., "Networked Human Motion Capture System Based on Quaternion Navigation"),
// with the errata of docs/design.md, "Errata: particle filter"; the method as implemented
// is in docs/accuracy.md, "Particle filter (pf)".
//
// Particle i carries an attitude q_i (q_earth_sensor) and a gyro bias b_i (rad/s). Every
// noise is a density, so what the filter does per second does not depend on the rate:
//   init     around the first TRIAD attitude q_m of accel + mag (not uniformly):
//            q_i = exp(δ_i/2) ⊗ q_m, δ_i ~ N(0, diag(init_tilt², init_tilt², init_heading²))
//            in the earth frame, b_i ~ N(0, bias_init²).
//   predict  q_i ← q_i ⊗ exp((ω − b_i) dt/2 + n_i/2), n_i ~ N(0, gyro_noise² dt) (angle
//            random walk); b_i ← b_i + N(0, bias_walk² dt).
//   detect   the default filter's detection (a MocapFilter run on the same samples, `detect`)
//            says whether the sensor rests and whether the field is disturbed, and estimates a
//            field offset fixed to the sensor, which is subtracted from the magnetometer.
//   weight   w_i ∝ w_i · p(z | x_i), one sample's σ being density / √dt:
//            tilt     ½ |a/g − u_i|² dt / meas_tilt², u_i = R_iᵀ e_z the particle's up
//                     direction (linear in the linear acceleration: it averages out);
//            heading  2 e_z² dt / meas_heading², e = vec(q_i ⊗ q_h*), q_h the estimate turned
//                     about the vertical until the horizontal field it sees points north;
//                     dropped while the detector rejects the field (counted);
//            rest     ½ |ω − b_i|² dt / gyro_noise² while the detector says the sensor rests.
//   resample systematic, when N_eff = 1/Σw_i² (erratum of eq. 13) < resample_frac · N.
//   regularise after resampling: in the chart x_i = (vec(q_i ⊗ m*), b_i) around the estimate
//            m, a Liu–West kernel from the cloud's empirical covariance C:
//            x_i ← a x_i + (1 − a) x̄ + reg_h L z_i, L Lᵀ = C, a = √(1 − reg_h²), which keeps the
//            cloud's mean and covariance (the attitude–bias correlation through which the bias
//            is learned included) and keeps the bias particles from drifting apart.
//   step 6   the moved particles are re-weighted by the current measurement's likelihood
//            alone (w_i ∝ p(z | x_i), not reset to 1/N) and the estimate is recomputed.
//   estimate Markley weighted average of the particles (markley_average.hpp), seeded with the
//            previous estimate; bias estimate Σ w_i b_i.
//
// Determinism: the same Params (seed included) and samples give bit-identical output on the
// same build. Random numbers come from an inline xoshiro256+ and a fixed table of normal
// quantiles (not std::normal_distribution, whose output is library-specific).
// Memory: all particle arrays (structure of arrays) are allocated in the constructor;
// update() never allocates. Cost: linear in N, about 6 µs per update at 256 particles on the
// build machines (docs/performance.md, "Filter update cost"), the detector included.
// Thread-safety: not thread-safe; one instance per sensor, pinned to a worker.
#pragma once

#include <cstdint>
#include <vector>

#include "filter/attitude_solver.hpp"
#include "filter/mocap_filter.hpp"
#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct ParticleFilterParams {
    int particles = 256;            ///< key "particles": particle count N (1..65536)
    std::uint64_t seed = 1;         ///< key "seed": random seed (same seed, same output)
    double gyro_noise = 0.01;       ///< key "gyro_noise": rate noise density of the propagation, rad/s/√Hz
    double bias_walk = 2e-4;        ///< key "bias_walk": bias random walk, rad/s/√s
    double bias_init_rad_s = 0.03;  ///< key "bias_init": σ of the initial bias particles, rad/s
    double meas_tilt = 0.05;        ///< key "meas_tilt": noise density of q_m's tilt, rad/√Hz
    double meas_heading = 0.08;     ///< key "meas_heading": noise density of q_m's heading, rad/√Hz
    double resample_frac = 0.5;     ///< key "resample_frac": resample when N_eff < frac · N
    double reg_h = 0.2;             ///< key "reg_h": kernel width / the cloud's covariance, in [0, 1)
    double init_tilt_rad = 0.05;    ///< key "init_tilt": σ of the initial cloud's tilt, rad
    double init_heading_rad = 0.2;  ///< key "init_heading": σ of the initial cloud's heading, rad
    double gravity_m_s2 = 9.81;     ///< key "gravity": g, m/s² (the tilt likelihood compares a/g)
    bool detect = true;             ///< key "detect": gate the likelihood with the default filter's
                                    ///< rest and magnetic-disturbance detection (and field-offset estimate)
    double max_step_s = 0.5;        ///< key "max_step_s": larger timestamp steps restart the time base
};

/// Observable state (besides the particles themselves).
struct ParticleFilterState {
    math::Quat q_earth_sensor = math::Quat::Identity();  ///< Markley average of the particles
    math::Vec3 gyro_bias_rad_s = math::Vec3::Zero();     ///< weighted mean bias
    double n_eff = 0.0;                                  ///< effective sample size after the last update
    double dt_s = 0.0;                                   ///< last sample period, s (weights a measurement)
    bool initialised = false;                            ///< particles drawn around a first q_m
    std::uint64_t resamples = 0;                         ///< resampling steps done
    std::uint64_t rejected_measurements = 0;             ///< samples not weighted (no accelerometer, or
                                                         ///< before the first attitude)
    std::uint64_t heading_gated = 0;                     ///< samples weighted for tilt only (field disturbed)
    std::uint64_t reinitialisations = 0;                 ///< weight collapse (all ~0): cloud redrawn
};

class ParticleFilter final : public OrientationFilter {
public:
    explicit ParticleFilter(const ParticleFilterParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override { return state_.q_earth_sensor; }
    [[nodiscard]] math::Vec3 gyro_bias_rad_s() const override { return state_.gyro_bias_rad_s; }
    /// The disturbance flags the likelihood is gated by (those of the detector, with detect).
    [[nodiscard]] FilterDiagnostics diagnostics() const override;
    void reset() override;
    [[nodiscard]] std::string_view name() const override { return "pf"; }
    [[nodiscard]] std::uint64_t gaps() const override { return clock_.gaps(); }

    [[nodiscard]] const ParticleFilterParams& params() const { return params_; }
    [[nodiscard]] const ParticleFilterState& state() const { return state_; }
    [[nodiscard]] int particle_count() const { return n_; }
    /// Particle i (0 <= i < particle_count()) and its normalised weight.
    [[nodiscard]] math::Quat particle(int i) const;
    [[nodiscard]] math::Vec3 particle_bias(int i) const;
    [[nodiscard]] double weight(int i) const;

private:
    struct Rng {  // xoshiro256+ (Blackman & Vigna), seeded through splitmix64
        std::uint64_t s[4];
        void seed(std::uint64_t x);
        std::uint64_t next();
    };
    // Fills noise_ with 6 planes of n_ standard normals (one table lookup each).
    void fill_noise();
    void initialise(const math::Quat& q_m);
    void predict(const math::Vec3& gyro, double dt);
    struct Measurement {
        math::Vec3 up_g = math::Vec3::UnitZ();          // specific force / g, sensor frame
        math::Quat q_heading = math::Quat::Identity();  // attitude whose heading is measured
        bool use_heading = false;                       // the field passed the detector
        const math::Vec3* rest_gyro = nullptr;          // at rest: the gyro reading (bias)
    };
    // Multiplies the weights by the likelihood of z (replaces them when `replace`);
    // false: weights collapsed.
    bool weigh(const Measurement& z, bool replace);
    void resample();
    void regularise();
    void estimate();

    ParticleFilterParams params_;
    int n_;
    MocapFilter detector_;  // the default filter's rest and disturbance detection (detect)
    // Structure of arrays, size n_ each; the *_tmp_ arrays are the resampling targets.
    std::vector<double> qw_, qx_, qy_, qz_, bx_, by_, bz_, w_, cost_;
    std::vector<double> qw_tmp_, qx_tmp_, qy_tmp_, qz_tmp_, bx_tmp_, by_tmp_, bz_tmp_;
    std::vector<double> noise_;  // 6 planes of n_ standard normals, refilled per use
    Rng rng_{};
    ParticleFilterState state_;
    SampleClock clock_;
};

}  // namespace mocap::filter
