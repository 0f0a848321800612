// mag_delay.hpp — the magnetometer's lag behind the gyroscope, estimated from the readings and
// taken out of them: over a whole recording (estimate_mag_delay, advance_mag: the offline
// re-solve), or online, sample by sample, for a causal filter (MagDelayTracker, mag_ahead).
//
// A MEMS magnetometer often reports the field some milliseconds later than the gyroscope
// reports the rate (its own output filter and conversion time). While the sensor turns at ω
// a lag d turns the measured field by ω·d: at 100 °/s a 10 ms lag is 1° of heading, and a
// causal filter sees it as a heading disturbance. The lag shows in the readings alone: a
// field fixed in the earth frame obeys dm/dt = −ω × m in the sensor frame, so the lag is
// the shift of the magnetometer series that best satisfies that equation against the gyro.
// On the six BROAD recordings the estimate is 2–3 samples at 285.7 Hz (7–11 ms) on every one,
// in agreement with the lag that best aligns the field's heading with the optical reference.
//
// Thread-safety: pure functions, and a value type (MagDelayTracker) owned by one filter.
// Cost: offline O(samples · candidates) with allocation for the output; online ~20 ns per
// sample, no allocation.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"

namespace mocap::filter {

/// Slowest rotation whose samples enter a lag estimate, rad/s: below it the field hardly
/// turns and the samples carry noise, not lag.
inline constexpr double kMagDelayMinRateRadS = 0.3;

struct MagDelayEstimate {
    double delay_s = 0.0;     ///< magnetometer lag behind the gyro, s (0 if not estimable)
    std::size_t samples = 0;  ///< samples that entered the estimate (turning, with a field reading)
};

/// Estimates the magnetometer lag from samples in time order: the shift d, from −1 sample
/// period to max_delay_s, minimising the mean of |dm/dt + ω × m|² over the samples that turn faster than
/// min_rate_rad_s (m read at t + d, linearly interpolated; dm/dt a central difference),
/// tried on a grid of the median sample period and refined by a parabola through the best
/// three, plus half a sample period: a gyro reading covers the step before its timestamp
/// (the filters integrate it over (t_prev, t]), so it is the rate half a step earlier. The
/// lag shows only where the rate changes (a lagged field under a constant rate obeys the
/// same equation): human motion has plenty. The result is clamped to [0, max_delay_s];
/// fewer than 100 usable samples, or no sample period, give delay 0.
MagDelayEstimate estimate_mag_delay(std::span<const ImuSample> samples, double max_delay_s,
                                    double min_rate_rad_s = kMagDelayMinRateRadS);

/// The samples with each magnetometer reading replaced by the reading at t + delay_s
/// (linear interpolation between the two readings around it; without a reading on either
/// side the sample is marked kImuNoMag; past the last sample the last reading is kept).
std::vector<ImuSample> advance_mag(std::span<const ImuSample> samples, double delay_s);

/// The field reading delay_s later, predicted from the rate: a field fixed in the earth frame
/// turns by −ω·delay in the sensor frame (the reading rotated by that angle; its norm kept).
/// A causal filter takes out a known lag this way without waiting for later readings.
math::Vec3 mag_ahead(const math::Vec3& mag_ut, const math::Vec3& gyro_rad_s, double delay_s);

/// The lag learned online, sample by sample (a causal filter cannot shift readings it has not
/// received yet). Linearised in the lag, a reading d late obeys
///   dm/dt + ω × m = d · (dω/dt × m),
/// so d is the regression coefficient of r = dm/dt + ω × m on g = dω/dt × m: exponentially
/// weighted least squares over the samples the caller declares usable (an undisturbed field)
/// that turn faster than kMagDelayMinRateRadS, forgetting only on those samples (a sensor at
/// rest keeps what it learned). r and g are central differences over the last three samples,
/// taken at the middle one; the rate there is the mean of the two readings around it, since
/// a gyro reading covers the step before its timestamp (as in estimate_mag_delay). Like the
/// offline estimate, it sees a lag only where the rate changes.
///
/// delay_s() stays 0 until the estimate has converged: at least kMinTurningS of usable
/// samples, and the standard error (from the residual scatter, as if the samples were
/// independent) below kConvergedStdErrS, about what 90 s of MEMS noise at 100 Hz allow; it
/// counts as converged until the error exceeds twice that, so the lag taken out does not
/// come and go with the scatter. Then it is the estimate clamped to [0, max_delay_s].
class MagDelayTracker {
public:
    static constexpr double kConvergedStdErrS = 0.005;
    static constexpr double kMinTurningS = 2.0;

    /// One sample: the bias-corrected rate, the field reading (the part that turns with the
    /// sensor) and whether it exists, the step since the previous sample (<= 0: no step, the
    /// history restarts), whether the field may enter the estimate, and the forgetting
    /// factor per usable sample (exp(−ts / window)).
    void update(const math::Vec3& gyro_rad_s, const math::Vec3& mag_ut, bool mag_ok, double dt_s, bool usable,
                double forgetting);
    /// The lag to take out, s: 0 until converged, then the estimate in [0, max_delay_s].
    [[nodiscard]] double delay_s(double max_delay_s) const;
    /// The unclamped least-squares estimate, s (0 before any usable sample).
    [[nodiscard]] double estimate_s() const { return sgg_ > 0.0 ? sgr_ / sgg_ : 0.0; }
    /// Its standard error, s (infinite before two usable samples).
    [[nodiscard]] double std_error_s() const;
    [[nodiscard]] bool converged() const { return converged_; }

private:
    std::array<math::Vec3, 2> gyro_{math::Vec3::Zero(), math::Vec3::Zero()};  ///< rates at t−1, t−2
    std::array<math::Vec3, 2> mag_{math::Vec3::Zero(), math::Vec3::Zero()};   ///< fields at t−1, t−2
    double dt_prev_s_ = 0.0;                                                  ///< step from t−2 to t−1
    int history_ = 0;         ///< consecutive samples with a field in gyro_ / mag_ (0..2)
    double n_ = 0.0;          ///< Σ weights
    double turning_s_ = 0.0;  ///< Σ weights · step, s
    bool converged_ = false;
    double sgg_ = 0.0;  ///< Σ g·g, (µT·rad/s²)², weighted as n_
    double sgr_ = 0.0;  ///< Σ g·r
    double srr_ = 0.0;  ///< Σ r·r, (µT/s)²
};

}  // namespace mocap::filter
