// heading_filter.hpp — the slow estimator of one joint's relative heading: the angle δ about
// the vertical that turns the child sensor's 6D earth frame into the parent sensor's, and
// the rate at which it drifts (docs/fusion.md, "Heading filter").
//
// Each segment's 6D orientation (inclination from gravity, heading from the gyro alone) has a
// heading of its own that drifts with the vertical part of its gyro error; δ is the difference
// of two such headings, so it drifts at the difference of two residual biases. State: δ (rad,
// wrapped to (−π, π]) and its rate r (rad/s), a two-state Kalman filter:
//   predict  δ ← δ + r·dt,  P ← F P Fᵀ + diag(σ_δ² dt, σ_r² dt)
//   update   a measurement z of δ with variance R: innovation wrap(z − δ), the usual gain;
//            an innovation beyond gate_sigma standard deviations is refused (counted).
// The measurements (joint_constraints.hpp, the magnetometer) are not independent from one
// sample to the next: their errors (inclination, axis, a model that is only nearly right)
// change on the time scale of the motion. The caller therefore scales each per-sample
// variance by correlation_s / dt, so the filter sees about one independent measurement per
// correlation time whatever the sample rate (40 Hz or 100 Hz give the same behaviour).
//
// Plain value, no allocation; not thread-safe (one per joint, on the assembler thread).
// Cost: a few dozen flops per call.
#pragma once

#include <cstdint>

namespace mocap::fusion {

struct HeadingFilterParams {
    double sigma_delta_deg_sqrt_s = 0.1;   ///< random walk of δ, °/√s (sets how fast δ follows the constraints)
    double sigma_rate_deg_s_sqrt_s = 0.2;  ///< random walk of the drift rate, (°/s)/√s: the filters' biases,
                                           ///< and so the rate, move by ~1.5 °/s in the first minute of a walk
    double rate_sigma_init_deg_s = 2.0;    ///< initial (and largest) drift-rate uncertainty, °/s: after a
                                           ///< short still period two filters' unlearned vertical gyro
                                           ///< biases differ by up to ~3.5 °/s (a simulated body after a
                                           ///< 2 s T-pose: 2.6 °/s pelvis–thigh, 3.5 °/s shank–foot)
    double rate_max_deg_s = 4.0;           ///< the drift rate is clipped to ± this, °/s
    double sigma_max_deg = 60.0;           ///< δ's uncertainty never grows beyond this, °
};

class HeadingFilter {
public:
    explicit HeadingFilter(const HeadingFilterParams& params = {}) : params_(params) {}

    /// Forgets everything: uninitialised.
    void reset();
    /// Starts from δ = delta_rad with standard deviation sigma_rad, rate 0.
    void init(double delta_rad, double sigma_rad);
    /// Starts δ again at delta_rad with standard deviation sigma_rad, keeping the drift rate
    /// and its uncertainty: one of the two 6D frames started again, but the gyro biases that
    /// make them drift apart did not. Before init, as init().
    void restart(double delta_rad, double sigma_rad);
    /// Moves the state dt_s forward (no-op before init or for dt_s <= 0).
    void predict(double dt_s);
    /// One measurement of δ with variance var_rad2 (> 0). Refused (returns false, counted in
    /// refused()) when |innovation| > gate_sigma · √(P + R), or before init.
    bool update(double z_rad, double var_rad2, double gate_sigma);

    [[nodiscard]] bool initialised() const { return initialised_; }
    [[nodiscard]] double delta_rad() const { return delta_; }
    [[nodiscard]] double rate_rad_s() const { return rate_; }
    /// Standard deviation of δ, rad (π before init).
    [[nodiscard]] double sigma_rad() const;
    [[nodiscard]] std::uint64_t refused() const { return refused_; }
    /// Shifts δ by d_rad (the caller re-based one of the two frames), keeping the uncertainty.
    void shift(double d_rad);

private:
    HeadingFilterParams params_;
    bool initialised_ = false;
    double delta_ = 0.0, rate_ = 0.0;
    double p00_ = 0.0, p01_ = 0.0, p11_ = 0.0;
    std::uint64_t refused_ = 0;
};

}  // namespace mocap::fusion
