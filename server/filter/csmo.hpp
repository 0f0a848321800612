// csmo.hpp — Complementary Sliding Mode Observer (Fourati, Manamanni, Afilal, Handrich),
// eq. 9–17 with the errata of docs/design.md, "Errata: CSMO".
//
// Each sample:
//   1. propagate with the gyroscope:   q⁻ = q ⊗ exp(ω dt / 2)
//   2. measure q_m from accel + mag by Levenberg–Marquardt (attitude_solver.hpp), warm-started
//      from q⁻ (a measurement the solver rejects skips steps 3–4 and is counted)
//   3. error, sensor side:            q_e = q⁻* ⊗ q_m   (sign chosen so q_e,w >= 0)
//   4. correction (switching + linear), multiplied onto the propagated quaternion
//      (eq. 11 corrects the derivative; in discrete time it is a product: docs/design.md, "Errata: CSMO"):
//        c_i = s · (k_i · clip(q_e,i / ρ, −1, 1) + k_{i+3} · q_e,i),   i = x, y, z
//        q = normalise(q⁻ ⊗ [1, c])
//      (eq. 16 is garbled in print; the boundary-layer saturation clip(q_e/ρ) is the erratum.)
//
// Gains. The paper's gains are per sample at its 100 Hz: the saturated switching term turns
// the estimate by up to 2·k = 0.11° per sample and axis, the linear term removes a fraction
// k4 = 0.09% of the error per sample (time constant ≈ 11 s at 100 Hz). At another rate the gains are
// scaled by s = dt · gain_rate_hz so the correction per SECOND, and hence the convergence time
// and the noise bandwidth, stay those of the paper. Inside the boundary layer the per-sample
// loop gain is k/ρ ≈ 3.3 (> 2), so on noiseless data the estimate chatters inside a band of
// about ±2·k ≈ ±0.1°: that is the paper's design, not a bug of this code.
//
// Reference field: with dip_deg finite the reference is the field at that inclination (the
// paper: 60°) and the magnetometer also pulls on tilt, as in the paper. With dip_deg NaN
// (the default) each sample's own dip (angle between its accel and mag) is used, so the
// magnetometer sets heading only; this is what real recordings need (the dip is site-specific).
//
// Thread-safety: not thread-safe (one instance per sensor, pinned to a worker).
// Cost: one LMA solve (lm_iterations, default 2) + two quaternion products, ~0.2 µs.
// No allocation after construction.
#pragma once

#include <cstdint>
#include <limits>

#include "filter/attitude_solver.hpp"
#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct CsmoParams {
    // Switching gains on the x, y, z parts of q_e (per sample at gain_rate_hz).
    double k1 = 1e-3;  ///< key "k1": switching gain, x
    double k2 = 1e-3;  ///< key "k2": switching gain, y
    double k3 = 1e-3;  ///< key "k3": switching gain, z
    // Linear gains on the x, y, z parts of q_e (per sample at gain_rate_hz).
    double k4 = 9e-4;             ///< key "k4": linear gain, x
    double k5 = 9e-4;             ///< key "k5": linear gain, y
    double k6 = 9e-4;             ///< key "k6": linear gain, z
    double rho = 3e-4;            ///< key "rho": boundary layer of the saturation (q_e units)
    double gain_rate_hz = 100.0;  ///< key "gain_rate_hz": rate the per-sample gains are tuned for
    // Initial estimate (normalised; default identity). The paper uses
    // (0.2, 0.5, 0.7, 0.3) normalised: set q0w..q0z to those four numbers.
    double q0w = 1.0;                                           ///< key "q0w": initial estimate, w
    double q0x = 0.0;                                           ///< key "q0x": initial estimate, x
    double q0y = 0.0;                                           ///< key "q0y": initial estimate, y
    double q0z = 0.0;                                           ///< key "q0z": initial estimate, z
    bool init_from_measurement = false;                         ///< key "init_meas": start from the first sample's q_m
                                                                ///< (TRIAD) instead of q0
    double dip_deg = std::numeric_limits<double>::quiet_NaN();  ///< key "dip_deg": field
                                                                ///< inclination below the horizon, deg (paper: 60); NaN
                                                                ///< = each sample's own dip
    double lm_lambda = 0.01;  ///< key "lm_lambda": LMA damping (docs/design.md, "Errata: LMA": 0.01)
    double lm_alpha = 1.0;    ///< key "lm_alpha": LMA step scale (docs/design.md, "Errata: LMA": 1)
    int lm_iterations = 2;    ///< key "lm_iterations": LMA iterations per sample (warm-started)
    double max_step_s = 0.5;  ///< key "max_step_s": larger timestamp steps restart the time base
};

/// Observable state; reset() returns it to the Params' initial estimate.
struct CsmoState {
    math::Quat q_earth_sensor = math::Quat::Identity();  ///< current estimate
    math::Quat q_measured = math::Quat::Identity();      ///< last accepted q_m (LMA)
    math::Vec3 q_error_vec = math::Vec3::Zero();         ///< vector part of the last q_e
    bool initialised = false;                            ///< the first sample has been seen
    std::uint64_t rejected_measurements = 0;             ///< samples whose accel/mag gave no q_m
};

class Csmo final : public OrientationFilter {
public:
    explicit Csmo(const CsmoParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override { return state_.q_earth_sensor; }
    void reset() override;
    [[nodiscard]] std::string_view name() const override { return "csmo"; }
    [[nodiscard]] std::uint64_t gaps() const override { return clock_.gaps(); }

    [[nodiscard]] const CsmoParams& params() const { return params_; }
    [[nodiscard]] const CsmoState& state() const { return state_; }
    /// Overrides the current estimate (e.g. from a calibration); keeps the time base.
    void set_orientation(const math::Quat& q_earth_sensor);

private:
    // Returns false if the sample's accel/mag give no measurement.
    bool measure(const ImuSample& sample, const math::Quat& start, math::Quat& q_m) const;

    CsmoParams params_;
    LmaParams lma_;
    math::Vec3 k_switch_, k_linear_;
    bool fixed_dip_;          // dip_deg finite
    math::Vec3 h_ref_fixed_;  // reference field for a fixed dip
    CsmoState state_;
    SampleClock clock_;
};

}  // namespace mocap::filter
