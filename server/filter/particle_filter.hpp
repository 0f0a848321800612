// particle_filter.hpp — regularised quaternion particle filter with gyro-bias state
// (Li et al., "Networked Human Motion Capture System Based on Quaternion Navigation"),
// with the erratum and the pitfalls of docs/design.md, "Errata: particle filter", handled.
//
// Particle i carries an attitude q_i (q_earth_sensor) and a gyro bias b_i (rad/s).
//   init     around the first measurement q_m (not uniformly): q_i = exp(δ_i/2) ⊗ q_m with
//            δ_i ~ N(0, diag(init_tilt², init_tilt², init_heading²)) in the earth frame,
//            b_i ~ N(0, bias_init²).
//   predict  q_i ← q_i ⊗ exp((ω − b_i + n_i) dt / 2), n_i ~ N(0, gyro_noise²);
//            b_i ← b_i + N(0, bias_walk² dt).
//   measure  q_m from accel + mag: TRIAD when dip_deg is NaN (each sample's own dip: then
//            the LMA's least-squares answer IS the TRIAD answer, at a third of the cost),
//            otherwise the LMA warm-started from the estimate. Skipped (counted) when the
//            specific-force norm is more than accel_gate away from gravity (linear
//            acceleration) or the sample has no usable magnetometer.
//   weight   earth-frame small-angle error e_i = 2 vec(q_i ⊗ q_m*) (w >= 0):
//            w_i ∝ w_i · exp(−½ (e_x² + e_y²)/meas_tilt² − ½ e_z²/meas_heading²), normalised.
//   resample systematic, when N_eff = 1/Σw_i² (erratum of eq. 13) < resample_frac · N.
//   regularise after resampling: q_i ← exp(σ_q n_i / 2) ⊗ q_i with
//            σ_q = max(min_jitter, reg_h · cloud spread) (without the floor the cloud
//            collapses and locks off even on clean data); the bias particles shrink toward
//            their mean (Liu–West, a = bias_shrink) and get jitter
//            max(min_bias_jitter, √(1−a²)·spread) (without shrinkage they drift away).
//   estimate Markley weighted average of the particles (markley_average.hpp), seeded with the
//            previous estimate; bias estimate = Σ w_i b_i.
//
// Determinism: the same Params (seed included) and samples give bit-identical output on the
// same build. Random numbers come from an inline xoshiro256+ and a fixed table of normal
// quantiles (not std::normal_distribution, whose output is library-specific).
// Memory: all particle arrays (structure of arrays) are allocated in the constructor;
// update() never allocates. Cost: ~25 ns per particle and update, linear in N (measured CPU
// time on the build machines: 64 → 1.9 µs, 256 → 6 µs, 1024 → 25 µs); rates above ~20 rad/s
// at 100 Hz take a slower sin/cos path.
// Thread-safety: not thread-safe; one instance per sensor, pinned to a worker.
#pragma once

#include <cstdint>
#include <limits>
#include <vector>

#include "filter/attitude_solver.hpp"
#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct ParticleFilterParams {
    int particles = 256;                  ///< key "particles": particle count N (1..65536)
    std::uint64_t seed = 1;               ///< key "seed": random seed (same seed, same output)
    double gyro_noise_rad_s = 0.05;       ///< key "gyro_noise": σ of the rate noise per particle, rad/s
    double bias_walk_rad_s2 = 2e-4;       ///< key "bias_walk": bias random walk, rad/s per √s
    double bias_init_rad_s = 0.03;        ///< key "bias_init": σ of the initial bias particles, rad/s
    double meas_tilt_rad = 0.06;          ///< key "meas_tilt": σ of q_m's tilt error, rad
    double meas_heading_rad = 0.15;       ///< key "meas_heading": σ of q_m's heading error, rad
    double resample_frac = 0.5;           ///< key "resample_frac": resample when N_eff < frac · N
    double reg_h = 0.3;                   ///< key "reg_h": regularisation kernel width / cloud spread
    double min_jitter_rad = 0.002;        ///< key "min_jitter": floor of the attitude jitter σ, rad
    double min_bias_jitter_rad_s = 5e-4;  ///< key "min_bias_jitter": floor of the bias jitter σ, rad/s
    double bias_shrink = 0.98;            ///< key "bias_shrink": Liu–West a in (0, 1]; 1 = no shrinkage
    double init_tilt_rad = 0.05;          ///< key "init_tilt": σ of the initial cloud's tilt, rad
    double init_heading_rad = 0.2;        ///< key "init_heading": σ of the initial cloud's heading, rad
    double accel_gate = 0.1;              ///< key "accel_gate": skip q_m when | |a|/g − 1 | exceeds this
    double gravity_m_s2 = 9.81;           ///< key "gravity": g used by the gate, m/s²
    double dip_deg = std::numeric_limits<double>::quiet_NaN();  ///< key "dip_deg": reference
                                                                ///< field inclination, deg; NaN (default) = each
                                                                ///< sample's own dip (TRIAD measurement)
    int lm_iterations = 2;    ///< key "lm_iterations": LMA iterations (finite dip_deg only)
    double max_step_s = 0.5;  ///< key "max_step_s": larger timestamp steps restart the time base
};

/// Observable state (besides the particles themselves).
struct ParticleFilterState {
    math::Quat q_earth_sensor = math::Quat::Identity();  ///< Markley average of the particles
    math::Vec3 gyro_bias_rad_s = math::Vec3::Zero();     ///< weighted mean bias
    math::Quat q_measured = math::Quat::Identity();      ///< last accepted q_m
    double n_eff = 0.0;                                  ///< effective sample size after the last update
    bool initialised = false;                            ///< particles drawn around a first q_m
    std::uint64_t resamples = 0;                         ///< resampling steps done
    std::uint64_t rejected_measurements = 0;             ///< samples without a usable q_m
    std::uint64_t reinitialisations = 0;                 ///< weight collapse (all ~0): redrawn around q_m
};

class ParticleFilter final : public OrientationFilter {
public:
    explicit ParticleFilter(const ParticleFilterParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override { return state_.q_earth_sensor; }
    [[nodiscard]] math::Vec3 gyro_bias_rad_s() const override { return state_.gyro_bias_rad_s; }
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
    bool weigh(const math::Quat& q_m);  // false: weights collapsed
    void resample();
    void regularise();
    void estimate();
    bool measure(const ImuSample& sample, math::Quat& q_m) const;

    ParticleFilterParams params_;
    int n_;
    LmaParams lma_;
    // Structure of arrays, size n_ each; the *_tmp_ arrays are the resampling targets.
    std::vector<double> qw_, qx_, qy_, qz_, bx_, by_, bz_, w_, cost_;
    std::vector<double> qw_tmp_, qx_tmp_, qy_tmp_, qz_tmp_, bx_tmp_, by_tmp_, bz_tmp_;
    std::vector<double> noise_;  // 6 planes of n_ standard normals, refilled per use
    Rng rng_{};
    ParticleFilterState state_;
    SampleClock clock_;
};

}  // namespace mocap::filter
