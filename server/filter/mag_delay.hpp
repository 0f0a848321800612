// mag_delay.hpp — the magnetometer's lag behind the gyroscope, estimated from a recording and
// taken out of it (offline only: compensating a lag needs the readings that come after).
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
// Thread-safety: pure functions. Cost: O(samples · candidates), allocation for the output.
#pragma once

#include <span>
#include <vector>

#include "core/imu_sample.hpp"

namespace mocap::filter {

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
                                    double min_rate_rad_s = 0.3);

/// The samples with each magnetometer reading replaced by the reading at t + delay_s
/// (linear interpolation between the two readings around it; without a reading on either
/// side the sample is marked kImuNoMag; past the last sample the last reading is kept).
std::vector<ImuSample> advance_mag(std::span<const ImuSample> samples, double delay_s);

}  // namespace mocap::filter
