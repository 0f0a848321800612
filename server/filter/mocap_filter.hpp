// mocap_filter.hpp — the product's default orientation filter ("mocap").
//
// Design (after VQF, Laidig & Seel 2022, re-derived for this interface):
//  * strapdown integration of the bias-corrected gyro rate into q_I_sensor, where I is an
//    "almost inertial" frame that drifts only with the gyro error;
//  * inclination: the specific force is rotated into I and low-pass filtered there
//    (2nd-order Butterworth, time constant tau_acc_s), so bursts of linear acceleration
//    average out while the sensor turns; the filtered vector is then aligned with the
//    vertical by a correction q_E'_I that touches inclination only. A push that keeps its
//    direction does not average out: the specific force's deviation from the low-passed
//    gravity is clipped at three running medians of that deviation (see "Linear
//    acceleration" below);
//  * heading: one angle delta about the vertical, corrected by a first-order filter
//    (tau_mag_s) from the horizontal direction of the magnetometer only, so a magnetic
//    error can never tilt the inclination;
//  * gyro bias: a 3-state Kalman filter fed at rest (rest detection from gyro + accel
//    deviations) and in motion (from the inclination corrections the accelerometer asks for;
//    a clipped sample's correction counts for less), and about the vertical, which no
//    accelerometer correction sees, from the heading corrections a trusted field asks for
//    (see "Vertical gyro bias" below);
//  * magnetic-disturbance guard: running references of field norm and dip angle; a field
//    that departs from them, or whose heading disagreement with the gyro-propagated heading
//    jumps by more than mag_heading_th_deg (a disturbance that turns the field without
//    changing its norm much; a disagreement that grows no faster than an unknown vertical
//    bias can make it is drift, not a disturbance: "Vertical gyro bias" below), is rejected
//    (gyro-only heading) for up to mag_max_rejection_time_s,
//    after which it is used with a reduced gain; a new field that stays consistent for
//    mag_new_time_s while the sensor moves becomes the reference (the user walked into
//    another room). Thresholds widen to mag_noise_margin standard deviations of the
//    measured field noise; when that noise is so large that no disturbance of the
//    configured size could be seen, the guard stands aside (mag_guard_blind) rather than
//    reject at random. Counters and flags are in MocapFilterState.
//  * field offset fixed to the sensor (a magnet it carries, a steel part of its mount): the
//    reading is c + b with b constant in the sensor frame, a field that no longer turns with
//    the gyro; least squares over mag_offset_tau_s of the field in the 6D earth frame against
//    the attitude gives b whenever the sensor turns, and b is subtracted from every reading
//    once it exceeds mag_offset_min of the field (fully from twice that, so it comes and goes
//    without a step). At rest the estimate is held. The guard above then sees the corrected
//    field; what the estimate cannot explain it still rejects.
//  * magnetometer lag: a MEMS magnetometer reports the field some milliseconds after the gyro
//    reports the rate (mag_delay.hpp); while the sensor turns, the late reading looks like a
//    heading error. The lag d is learned online from the readings alone (MagDelayTracker:
//    least squares on dm/dt + ω × m = d·(dω/dt × m) over turning samples with an accepted
//    field, a 60 s window) and each reading is predicted d ahead by turning it with the
//    rate, so no latency is added. See "Magnetometer lag" below.
//
// Output: q_earth_sensor = Rz(delta) ⊗ q_E'_I ⊗ q_I_sensor, ENU.
//
// Start: the first sample gives the attitude in closed form (gravity + horizontal field);
// during the first tau_acc_s / tau_mag_s the corrections are running means of the readings
// so far (the horizontal field as a vector mean, unbiased even when the noise is as large
// as the field), so the filter does not spend seconds converging.
//
// Time: filter coefficients are computed from the sample period measured on the samples'
// own timestamps and recomputed when it drifts by more than 2 %.
//
// Time constants (trade-off): heading noise from the magnetometer falls as
// 1/sqrt(tau_mag_s), gyro drift grows with it; a long tau_acc_s rejects longer linear
// accelerations but lets gyro noise tilt the estimate longer. The defaults (3 s as in VQF;
// 12 s, longer than VQF's 9 s because on real recordings the magnetometer's residual
// calibration error costs more heading than the gyro drifts: BROAD mean 2.22° -> 2.10°, no
// recording worse; 13 s and more let an unlearned gyro bias turn a still sensor by over 0.2°)
// suit MEMS sensors, whose errors are linear acceleration and magnetic disturbance rather
// than white noise. A gyro whose measured white-noise floor is
// far above MEMS grade (gyro_noise_ref_deg_s) gets proportionally shorter time constants,
// the heading one towards its noise-optimal value σ_heading / σ_gyro: on the Fourati
// benchmark (gyro noise 0.4 rad/s, magnetometer noise 80 % of the field) that is ~0.3 s
// and ~5 s. The floor is the quietest 1 s of the last minutes, so vigorous human motion is
// not mistaken for noise.
//
// Bias in motion: the accelerometer's corrections measure the bias wherever the sensor turns,
// so a sensor that never rests still learns it. bias_sigma_motion_deg_s sets how fast: 0.03 °/s
// (VQF uses 0.1) learns 1.15 °/s per axis to within ~0.2 °/s in 30-60 s of continuous
// rotation (the `continuous` scenario, median total 2.8° -> 1.2°, Madgwick 1.4°) and improves
// every one of the six BROAD recordings of docs/accuracy.md (mean 2.10° -> 2.01°). Below
// 0.025 the fast combined recording, whose linear accelerations the corrections then take for
// bias, gets worse fast. The measurement waits for the end of the start-up averaging of the
// low-passes: the corrections before it are the initial alignment, and a bias learned from
// them left a still sensor 0.28° off after 30 s.
//
// Linear acceleration: the low-pass averages out linear acceleration that comes and goes, but a
// push that keeps one earth direction for a second (a limb's swing starting or stopping, a
// carried sensor that is set off) moves the low-passed vector as if gravity had tilted, by
// up to ~3° for 1 s of 3.5 m/s², for the several seconds of the low-pass's memory, and the motion
// bias measurement takes the corrections for gyro bias (the `bursts` scenario: Table I's
// rotation with eight 1 s pushes of 2-5 m/s²; median total 3.1°, Madgwick 2.0°, whose
// normalised gradient step limits what one push can do). Such a push stands out from the
// deviations the motion usually makes, so the deviation of the specific force from the
// low-passed gravity (in I) is clipped, keeping its direction (a Huber weight), at three
// running medians of that deviation, never below 0.5 m/s², before it enters the low-pass; a
// clipped sample's motion bias measurement has its variance multiplied by (deviation / clip)².
// The median, not a mean square, so the pushes hardly raise it; it moves by at most a factor
// e per second, so within seconds of vigorous motion it has risen to it, and motion whose
// deviations are large throughout is averaged as before (a weight on the size of each
// deviation against a fixed scale biases that average: 1 / (1 + (deviation / 2 m/s²)²) took
// the fast combined BROAD recording from 2.7° to 15.6°). A low-pass that is itself off (a
// gyro glitch) sees a deviation that persists, which raises the median until the clip lets
// go; during the start-up averaging there is no reference to judge a sample by, so nothing is
// clipped there. Measured: `bursts` median 3.1° -> 1.7° (seeds 1-5, Madgwick 2.0°; 1.8° over
// seeds 1-15); BROAD mean 1.81° -> 1.79° (tapping 1.36° -> 1.20°, no recording worse by more
// than 0.02°, 1.5-3.1 % of their moving samples clipped); `continuous` clips nothing. Three
// medians, 0.5 m/s² and e per second sit in a flat region: 2.5-4 medians, 0.3-0.8 m/s² and e
// per 0.5-2 s keep the BROAD mean within 0.01° and `bursts` at 1.5-2.0° (docs/accuracy.md,
// "Linear acceleration").
//
// Vertical gyro bias: an unlearned bias r about the vertical turns the 6D frame at r; the field
// seen in it turns at −r and the first-order heading correction lags it by r·tau_mag_s for as
// long as the bias lasts. A bias that rest did not teach (a T-pose shorter than rest_min_time_s,
// a sensor that never rests) of 1-2 °/s made that 12-24°: the heading guard, which flagged any
// disagreement beyond mag_heading_th_deg, took it for a disturbance and refused a clean field for
// up to mag_max_rejection_time_s while the heading drifted on the gyro (a simulated walk after a
// 2 s T-pose: pelvis 52°, calf 74° off after 38 s). Two changes, both from the same model:
//  - the heading corrections measure the bias: a second correction loop with the same gain,
//    run on the field while it is trusted and restarted after each rejection, has a correction
//    rate that is a known low-pass of R·(b − b̂) about the vertical (the accelerometer
//    measurement's structure, update_heading_bias), fed to the same Kalman filter with the
//    motion measurement's σ (bias_sigma_motion_deg_s), made larger where the field varies from
//    place to place or with the sensor's calibration (the variance of its norm and dip about the
//    reference, low-passed over 2 s, taken as the heading's: one independent value per
//    tau_mag_s). The steady lag is gone once the bias is learned (10-30 s in a clean field);
//  - the heading guard flags a jump, not a level: its reference follows the disagreement as far
//    as the heading correction and a vertical drift of two standard deviations of the bias that
//    the rest measurements leave unknown (bias_clip_deg_s at first) can move it, and is held
//    while the field is flagged. A sensor that has rested sees the level test it always had.
// Measured (docs/accuracy.md, "Vertical gyro bias"): the walk after a 2 s T-pose, pelvis / right
// calf / left upper arm 13° / 19° / 10° off at 38 s instead of 49° / 73° / 22°, within 5° by
// 90 s, no clean field refused; the pendulum scenario (no rest) 2.23° -> 1.21° per segment,
// 2.95° -> 1.45° per joint (seeds 1-10); the chain scenario (rests between moves) 6.14° ->
// 6.15° and 7.26° -> 7.25°; BROAD mean 1.79° -> 1.82° (no recording worse by more than 0.07°);
// `magnetic` 0.99° -> 0.94°. What is left: the accelerometer's corrections in cyclic motion
// can make the filter confident of a wrong vertical bias, which the heading's measurement then
// takes a minute or more to undo.
//
// Magnetometer lag: on the six BROAD recordings of docs/accuracy.md the learned lag is
// 10.4–12.5 ms (converged 2–15 s after the motion starts), as the offline estimate finds.
// Taking all of it out makes the field's heading, seen through the optical reference, more
// consistent on every recording, yet the filter's heading error falls on some (fast rotation
// 1.79° -> 1.59°) and rises on the fast ones with translation or near a magnet (stationary
// magnet 1.77° -> 2.76°), where the field's heading also carries the filter's tilt error
// (at these recordings' 70° dip, 1° of tilt is 2.7° of heading). Taking out 0.4 of it
// (mag_delay_share) lowers the mean from 2.01° to 1.81° with no recording worse by more than
// 0.17° (the stationary-magnet one); 0.5 gives 1.80° but +0.27° there, too close to the 0.3°
// a parameter may cost one recording to hold on another of that kind; 0.6 1.81° and +0.39°.
// The simulated scenarios have no lag and learn none (docs/accuracy.md, "Magnetometer lag").
//
// Thread-safety: none (one instance per worker). Cost: ~0.3 µs per update (docs/
// performance.md; the field-offset estimate adds about 10 %, the magnetometer lag about 12 %,
// the clip of linear acceleration about 2 %), no allocation.

#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "filter/mag_delay.hpp"
#include "filter/orientation_filter.hpp"

namespace mocap::filter {

struct MocapFilterParams {
    double tau_acc_s = 3.0;   ///< key "tau_acc_s": inclination correction time constant, s
    double tau_mag_s = 12.0;  ///< key "tau_mag_s": heading correction time constant, s

    bool rest_bias = true;                   ///< key "rest_bias": estimate gyro bias while at rest
    bool motion_bias = true;                 ///< key "motion_bias": estimate gyro bias (horizontal axes) in motion
    double bias_sigma_init_deg_s = 0.5;      ///< key "bias_sigma_init_deg_s": initial bias std, °/s
    double bias_forgetting_time_s = 100.0;   ///< key "bias_forgetting_time_s": time for the bias
                                             ///< uncertainty to grow back by 0.1·init, s
    double bias_clip_deg_s = 2.0;            ///< key "bias_clip_deg_s": |bias| limit per axis, °/s
    double bias_sigma_motion_deg_s = 0.03;   ///< key "bias_sigma_motion_deg_s": motion bias
                                             ///< measurement std, °/s (see "Bias in motion")
    double bias_vertical_forgetting = 1e-4;  ///< key "bias_vertical_forgetting": relative weight of
                                             ///< the (unobservable) vertical axis in motion, 0..1
    double bias_sigma_rest_deg_s = 0.03;     ///< key "bias_sigma_rest_deg_s": rest bias
                                             ///< measurement std, °/s
    double rest_min_time_s = 1.5;            ///< key "rest_min_time_s": stillness needed to declare rest, s
    double rest_filter_tau_s = 0.5;          ///< key "rest_filter_tau_s": rest detection low-pass, s
    double rest_th_gyro_deg_s = 2.0;         ///< key "rest_th_gyro_deg_s": gyro deviation threshold, °/s
    double rest_th_acc_m_s2 = 0.5;           ///< key "rest_th_acc_m_s2": accel deviation threshold, m/s²

    double gyro_noise_ref_deg_s = 2.0;  ///< key "gyro_noise_ref_deg_s": per-sample gyro white noise
                                        ///< the taus are meant for; a measured noise floor above it
                                        ///< shortens tau_acc_s in proportion and moves tau_mag_s
                                        ///< towards its noise-optimal value. 0 disables, °/s

    bool mag_guard = true;                    ///< key "mag_guard": reject magnetometer readings that disagree with
                                              ///< the reference field norm / dip
    double mag_current_tau_s = 0.05;          ///< key "mag_current_tau_s": low-pass of the field vector
                                              ///< (earth frame) before norm / dip are compared, s
    double mag_ref_tau_s = 20.0;              ///< key "mag_ref_tau_s": adaptation of the reference, s
    double mag_norm_th = 0.1;                 ///< key "mag_norm_th": relative norm deviation threshold
    double mag_dip_th_deg = 10.0;             ///< key "mag_dip_th_deg": dip deviation threshold, °
    double mag_noise_margin = 4.0;            ///< key "mag_noise_margin": thresholds are widened to this
                                              ///< many standard deviations of the filtered field noise
    double mag_heading_th_deg = 10.0;         ///< key "mag_heading_th_deg": a jump of the heading disagreement
                                              ///< (low-passed) beyond this, past what the gyro's drift explains,
                                              ///< flags a disturbance even when norm and dip look normal; it
                                              ///< clears back within half of it. 0 disables, °
    double mag_heading_tau_s = 1.0;           ///< key "mag_heading_tau_s": low-pass of that disagreement, s
    double mag_new_time_s = 20.0;             ///< key "mag_new_time_s": a consistent new field is accepted
                                              ///< after this much time in motion, s
    double mag_new_first_time_s = 5.0;        ///< key "mag_new_first_time_s": same, for the first field, s
    double mag_new_min_gyro_deg_s = 20.0;     ///< key "mag_new_min_gyro_deg_s": motion needed for the
                                              ///< new-field timer to run, °/s
    double mag_min_undisturbed_time_s = 0.5;  ///< key "mag_min_undisturbed_time_s": agreement time
                                              ///< before the field counts as undisturbed, s
    double mag_max_rejection_time_s = 60.0;   ///< key "mag_max_rejection_time_s": longest full
                                              ///< rejection, s
    double mag_rejection_factor = 2.0;        ///< key "mag_rejection_factor": gain divisor after the
                                              ///< rejection time, and the recovery rate of that time
    double mag_offset_tau_s = 20.0;           ///< key "mag_offset_tau_s": window of the estimate of a field
                                              ///< offset fixed to the sensor (a magnet it carries), s;
                                              ///< 0 disables
    double mag_offset_ridge = 0.15;           ///< key "mag_offset_ridge": shrinks the offset components
                                              ///< the window's rotation does not reveal, 0..1
    double mag_offset_min = 0.04;             ///< key "mag_offset_min": an offset below this fraction of the
                                              ///< field norm is not applied (calibration residue); it is
                                              ///< applied in full from twice this
    double mag_delay_s = -1.0;                ///< key "mag_delay_s": magnetometer lag behind the gyro taken out
                                              ///< of every reading, s, at most 0.05 (see "Magnetometer lag");
                                              ///< negative: learned from the readings, 0: none
    double mag_delay_share = 0.4;             ///< key "mag_delay_share": share of a learned lag taken out, 0..1
    double max_step_s = 0.5;                  ///< key "max_step_s": larger timestamp steps restart the time base, s

    /// Empty if every value is usable, else a message naming the first bad key.
    [[nodiscard]] std::string check() const;
};

/// Coefficients of a second-order Butterworth low-pass (a0 = 1).
struct LowPassCoeffs {
    std::array<double, 3> b{1.0, 0.0, 0.0};
    std::array<double, 2> a{0.0, 0.0};
};

/// Second-order Butterworth low-pass over N channels (direct form II transposed). The first
/// tau seconds are averaged and the filter starts in steady state on that average, so its
/// output never depends on one sample. Part of MocapFilterState.
template <int N>
struct LowPassState {
    std::array<double, std::size_t{2} * N> z{};  ///< filter memory
    std::array<double, N> sum{};                 ///< running sum during the initial averaging
    std::array<double, N> out{};                 ///< last output
    int count = 0;                               ///< samples averaged so far
    bool running = false;                        ///< initial averaging done
};

struct MocapFilterState {
    math::Quat q_i_sensor = math::Quat::Identity();  ///< gyro strapdown (almost inertial frame I)
    math::Quat q_e6_i = math::Quat::Identity();      ///< inclination correction (I -> 6D earth frame)
    double delta_rad = 0.0;                          ///< heading correction about the vertical
    math::Vec3 bias_rad_s = math::Vec3::Zero();      ///< gyro bias estimate, sensor frame
    math::Mat3 bias_p = math::Mat3::Zero();          ///< bias covariance, (0.01 °/s)²
    double vertical_bias_var = 0.0;                  ///< variance of the bias about the vertical as the rest
                                                     ///< measurements know it, (0.01 °/s)² (bias_clip² at first)
    bool initialised = false;                        ///< first sample seen

    double ts_s = 0.0;           ///< sample period the coefficients were computed for (0: unknown)
    double ts_lp_s = 0.0;        ///< smoothed measured sample period
    double tau_acc_eff_s = 0.0;  ///< tau_acc_s in use (see gyro_noise_ref_deg_s)
    double tau_mag_eff_s = 0.0;  ///< tau_mag_s in use

    // Gyro white-noise floor (second differences)
    std::array<math::Vec3, 2> gyro_prev{math::Vec3::Zero(), math::Vec3::Zero()};
    int gyro_history = 0;
    std::uint64_t gyro_noise_count = 0;
    double gyro_noise_var_lp = 0.0;     ///< per-axis noise variance, low-passed over 1 s, (rad/s)²
    double gyro_noise_floor_var = 0.0;  ///< its floor (falls at once, rises over 300 s)

    LowPassState<3> acc_lp;            ///< specific force in I
    double acc_dev_median_m_s2 = 0.0;  ///< running median of |specific force - acc_lp| (0: none yet)
    double acc_clip = 1.0;             ///< share of the last sample's deviation let through, 0..1
    LowPassState<9> bias_r_lp;         ///< rotation matrix for motion bias estimation
    LowPassState<2> bias_b_lp;         ///< R·bias (horizontal components)

    // Rest detection
    LowPassState<3> rest_gyro_lp;
    LowPassState<3> rest_acc_lp;
    double rest_time_s = 0.0;
    bool rest_detected = false;

    // Magnetic disturbance guard
    LowPassState<3> mag_lp;                        ///< field in the 6D earth frame
    double mag_noise_var = 0.0;                    ///< per-axis variance of the raw field around mag_lp
    double mag_dis_lp_rad = 0.0;                   ///< low-passed heading disagreement
    math::Vec3 field_dir_lp = math::Vec3::Zero();  ///< the horizontal field's direction in the 6D frame,
                                                   ///< low-passed over mag_heading_tau_s (0: none yet)
    double mag_dis_drift_rad = 0.0;                ///< that disagreement as the gyro's drift alone could have moved
                                                   ///< it (follows it at most at the drift rate, held while flagged)
    double mag_dis_var = 0.0;                      ///< variance of the raw disagreement around it, rad²
    std::uint64_t mag_stat_count = 0;              ///< samples in the noise statistics (fast start)
    bool mag_heading_disturbed = false;            ///< flagged by the heading disagreement
    bool mag_guard_blind = false;                  ///< field noise too large to detect a disturbance of
                                                   ///< the configured size: guard not applied
    double mag_norm = 0.0;                         ///< filtered field norm
    double mag_dip_rad = 0.0;                      ///< filtered dip angle (positive: field points down)
    double mag_dev_norm_ut = 0.0;  ///< accepted field's departure from the reference norm, low-passed, µT
    double mag_dev_dip_ut = 0.0;   ///< the same for the dip (times the norm), µT
    double mag_var_ut2 = 0.0;      ///< variance of that departure, per axis, µT²
    double mag_ref_norm = 0.0;     ///< reference norm (0: none yet)
    double mag_ref_dip_rad = 0.0;
    double mag_candidate_norm = -1.0;  ///< candidate new field (-1: none)
    double mag_candidate_dip_rad = 0.0;
    double mag_candidate_time_s = 0.0;
    double mag_undisturbed_time_s = 0.0;
    double mag_reject_time_s = 0.0;
    bool mag_disturbed = true;  ///< norm / dip off the reference (true until one exists)
    bool mag_settled = true;    ///< the heading agrees with the field again since the last rejection
    double k_mag_init = 1.0;    ///< initial-convergence gain 1/N (0 when done)
    double last_mag_disagreement_rad = 0.0;
    math::Vec3 mag_horizontal_lp = math::Vec3::Zero();  ///< horizontal field in the 6D earth frame, averaged
                                                        ///< over tau_mag_s (vector mean at the start)

    // Vertical gyro bias from the heading corrections (update_heading_bias): a loop like the
    // heading correction's that follows the field while it is trusted, and its response to the bias
    bool hb_running = false;                  ///< the loop follows the field (restarts after each rejection)
    double hb_delta_rad = 0.0;                ///< its heading, 6D earth frame
    double hb_k = 0.0;                        ///< its gain per sample (restarts when the gain changes)
    math::Vec3 hb_r_lp = math::Vec3::Zero();  ///< the vertical row of R (sensor -> 6D earth), low-passed by it
    double hb_rb_lp = 0.0;                    ///< the same for the vertical component of R·bias, rad/s

    // Field offset fixed to the sensor (update_mag_offset): weighted sums of the least squares
    double mag_off_n = 0.0;                         ///< Σ weights
    math::Mat3 mag_off_r = math::Mat3::Zero();      ///< Σ R (sensor -> 6D earth)
    math::Vec3 mag_off_sum_e = math::Vec3::Zero();  ///< Σ field in the 6D earth frame, µT
    math::Vec3 mag_off_sum_s = math::Vec3::Zero();  ///< Σ field in the sensor frame, µT
    math::Vec3 mag_offset_ut = math::Vec3::Zero();  ///< estimated offset, µT
    double mag_offset_weight = 0.0;                 ///< share of it subtracted from readings, 0..1

    // Magnetometer lag (take_out_mag_delay)
    MagDelayTracker mag_delay;  ///< the lag learned from the readings (mag_delay_s < 0)
    double mag_delay_s = 0.0;   ///< lag taken out of the last reading, s

    // Counters (only go up until reset())
    std::uint64_t samples = 0;
    std::uint64_t mag_samples_rejected = 0;  ///< mag readings not used (disturbed, gain 0)
    std::uint64_t mag_disturbances = 0;      ///< transitions undisturbed -> disturbed (either test)
    std::uint64_t mag_fields_accepted = 0;   ///< new reference fields adopted
    std::uint64_t no_mag_samples = 0;        ///< samples without a magnetometer reading
    std::uint64_t zero_acc_samples = 0;      ///< samples with a zero accelerometer reading
    std::uint64_t acc_samples_clipped = 0;   ///< accelerometer deviations clipped as linear acceleration
    std::uint64_t heading_bias_samples = 0;  ///< heading corrections used as a measurement of the bias
    std::uint32_t attitude_restarts = 0;     ///< attitude started again after a gap (restart_attitude)

    SampleClock clock = SampleClock(0.5);  ///< time base (max step set from Params)
};

class MocapFilter final : public OrientationFilter {
public:
    explicit MocapFilter(const MocapFilterParams& params = {});

    void update(const ImuSample& sample) override;
    [[nodiscard]] math::Quat orientation() const override;
    [[nodiscard]] math::Vec3 gyro_bias_rad_s() const override { return state_.bias_rad_s; }
    [[nodiscard]] FilterDiagnostics diagnostics() const override;
    [[nodiscard]] HeadingSplit heading_split() const override;
    void reset() override;
    [[nodiscard]] std::string_view name() const override { return "mocap"; }
    [[nodiscard]] std::uint64_t gaps() const override { return state_.clock.gaps(); }

    [[nodiscard]] const MocapFilterParams& params() const { return params_; }
    [[nodiscard]] const MocapFilterState& state() const { return state_; }
    /// Inclination-only estimate q_E'_sensor (no heading correction).
    [[nodiscard]] math::Quat orientation_6d() const;
    /// True while magnetometer readings are being rejected or down-weighted.
    [[nodiscard]] bool mag_rejected() const { return state_.mag_disturbed || state_.mag_heading_disturbed; }

private:
    void compute_coeffs(double ts_s);
    void update_gyro(const math::Vec3& gyro, double dt_s);
    void restart_attitude();
    void update_acc(const math::Vec3& acc);
    void clip_acc_deviation(math::Vec3& acc_i);
    void update_mag(const math::Vec3& mag, const math::Vec3& rate_rad_s, double dt_s);
    math::Vec3 take_out_mag_delay(const math::Vec3& mag, const math::Vec3& rate_rad_s, double dt_s);
    void update_mag_guard(const math::Vec3& mag_earth);
    void update_bias(const math::Vec3& acc_earth_unit);
    void update_heading_guard();
    void update_heading_bias(const math::Vec3& h, const math::Mat3& r_e6_s, bool trusted);
    void update_mag_offset(const math::Vec3& mag_s, const math::Mat3& r_e_s);
    void adapt_time_constants();
    void accept_candidate_field();

    MocapFilterParams params_;
    MocapFilterState state_;
    // Derived coefficients, functions of params_ and state_.ts_s.
    LowPassCoeffs acc_lp_, rest_lp_, mag_current_lp_;
    double k_mag_ = 0.0, k_mag_ref_ = 0.0, k_mag_noise_ = 0.0, k_dis_ = 0.0;
    double k_noise_fast_ = 0.0, k_noise_floor_ = 0.0, k_mag_offset_ = 0.0, mag_delay_forgetting_ = 1.0;
    double acc_dev_median_step_ = 1.0;
    double bias_p0_ = 0.0, bias_v_ = 0.0, bias_motion_w_ = 0.0, bias_vertical_w_ = 0.0, bias_rest_w_ = 0.0;
    double k_field_dev_ = 0.0, vertical_bias_var0_ = 0.0;
};

}  // namespace mocap::filter
