// offline_smoother.hpp — a non-causal re-solve of a whole recording from a causal
// orientation filter (mocap-filter --offline), for users who re-process a take after the
// shoot.
//
// Method (a forward-backward smoother of a causal filter; each pass's covariance is replaced
// by what the pass itself shows: how long it has run and how well the field agrees with it):
//  1. Magnetometer lag: estimated from the readings and taken out (mag_delay.hpp), which
//     needs the readings that come after and so is possible only offline.
//  2. Forward pass: the filter over the samples in time order: estimate f_i.
//  3. Backward pass: the filter reset and run from the last sample to the first (the same
//     motion played backwards: gyro negated, the reading that covered each interval;
//     accelerometer and magnetometer as they are): estimate b_i. Each pass lags the truth
//     from its own side (heading corrections, bias learning, start-up), so their errors
//     differ in sign where it matters.
//     Without a magnetometer the two passes' headings are unrelated (each keeps its first
//     sample's): the backward pass is turned about the vertical into the forward pass's frame
//     first, by the circular mean of their heading difference once both have settled (both
//     integrate the same gyro, so the difference hardly changes), and the blend below keeps
//     the forward pass's heading (the passes' tilt corrections differ under large
//     accelerations, and so do their headings by a few degrees); with a field, the field
//     gives both the same frame.
//  4. Blend: q_i = Markley average of f_i and b_i with weights 1/σ² (math::average_two).
//     A pass's σ² at sample i is
//        sigma_floor² + sigma_start²·exp(−2 s/converge_tau_s) + e²
//     with s the time the pass has run (a pass just started, with its start-up transient,
//     counts little: early samples trust the backward pass, late ones the forward pass), and
//     e² the pass's heading error variance over ±residual_window_s seen in the field readings:
//     a reading's heading through the pass's estimate (less the field offset the filter
//     subtracts, mag_offset_ut) is r = φ − e, the field's own heading error φ (noise, motion,
//     calibration, common to both passes) less the pass's error e, so e² = mean(r²) −
//     mean(r_f·r_b) (at least 0): the common φ² no longer evens out the weights of a pass that
//     is off and one that is not. Disturbances: e² counts the samples whose field both passes
//     took as undisturbed by norm and dip (FilterDiagnostics::mag_field_disturbed) and at
//     least one used (not mag_rejected), since a disturbed field would favour the pass that
//     follows it; one pass's rejection of the field as a heading disturbance does not exempt
//     it, because that is how a pass far off in heading sees the clean field (a take ending
//     near a magnet: the backward pass starts off and can reject the clean field for a
//     minute). Where no such sample is in the window the passes are blended by their run
//     time alone.
//
// Any OrientationFilter works (it is driven only through the interface); with the default
// "mocap" filter this is the product's offline re-solve. On the six BROAD recordings: mean
// total RMSE 1.62° against 2.01° for the same filter online (docs/accuracy.md).
//
// API for batch callers (the mocap-filter tool; replay of one subject's segment): hand in
// one sensor's samples in strictly increasing time order (gaps allowed: the filter's own
// max_step rule applies in both passes) and a filter configured as the online one would be.
// smooth() resets the filter, uses it for both passes and leaves it in an unspecified state;
// the samples are not modified; the result has one estimate per sample, in sample order,
// q_earth_sensor in ENU. It is deterministic: the same samples and a freshly built filter
// with the same parameters give bit-identical output (a filter reused after another run
// differed by ~1e-8 in a test: MocapFilter::reset() leaves its derived coefficients as the
// last run set them).
//
// Thread-safety: an OfflineSmoother holds only Params; smooth() is const and may run on
// several threads, each with its own filter. Cost: the lag search (one cheap pass of a few
// vector operations per sample for each candidate lag, 16 at 285.7 Hz), two filter passes
// and one two-quaternion average per sample: 0.9 µs per sample against 0.37 µs for one
// online update (docs/accuracy.md); memory O(samples). Not for the live
// pipeline: it needs the whole take.
#pragma once

#include <span>
#include <vector>

#include "core/imu_sample.hpp"
#include "filter/orientation_filter.hpp"
#include "math/quaternion.hpp"

namespace mocap::filter {

struct OfflineSmootherParams {
    double mag_delay_max_s = 0.05;    ///< longest magnetometer lag estimated and removed, s (0: none)
    double converge_tau_s = 3.0;      ///< time constant of a pass's start-up uncertainty, s
    double sigma_floor_deg = 1.0;     ///< uncertainty of a converged pass, °
    double sigma_start_deg = 30.0;    ///< uncertainty of a pass on its first sample, °
    double residual_window_s = 30.0;  ///< half-width of the heading-residual window, s (0: not used)
};

/// One smoothed recording.
struct OfflineResult {
    std::vector<math::Quat> orientation;  ///< q_earth_sensor (ENU) per sample, unit norm
    std::vector<double> forward_weight;   ///< share of the forward pass in each estimate, 0..1
    std::vector<char> mag_used;           ///< either pass used the field for heading at the sample
    double mag_delay_s = 0.0;             ///< magnetometer lag removed before the passes, s
    /// Without a field in either pass: the heading turn applied to the backward pass to bring
    /// it into the forward pass's frame (0 when a field fixed both), rad.
    double backward_heading_offset_rad = 0.0;
};

class OfflineSmoother {
public:
    explicit OfflineSmoother(const OfflineSmootherParams& params = {}) : params_(params) {}

    /// Re-solves `samples` (one sensor, strictly increasing timestamps) with `filter`.
    /// Empty input gives an empty result.
    [[nodiscard]] OfflineResult smooth(OrientationFilter& filter, std::span<const ImuSample> samples) const;

    [[nodiscard]] const OfflineSmootherParams& params() const { return params_; }

private:
    OfflineSmootherParams params_;
};

}  // namespace mocap::filter
