// imu_sample.hpp — one timestamped 9-axis sample from one sensor node.
//
// Units (docs/style.md, "Units in names"): seconds are never stored; the timestamp is integer
// microseconds on the clock of whoever produced the sample (the sink for live data,
// the file for recordings). Nothing in this header reads a clock.
// Thread-safety: plain value type.
#pragma once

#include <array>
#include <cstdint>

namespace mocap {

using Vec3d = std::array<double, 3>;

/// Flags a sample may carry. Bit set = condition present.
enum ImuSampleFlags : std::uint8_t {
    kImuNoMag = 1u << 0,           ///< magnetometer reading missing or invalid this instant
    kImuAccelSaturated = 1u << 1,  ///< at least one accelerometer axis at full scale
    kImuGyroSaturated = 1u << 2,   ///< at least one gyroscope axis at full scale
};

/// One 9-axis sample in the sensor frame.
struct ImuSample {
    std::int64_t t_us = 0;   ///< sample instant, microseconds
    Vec3d gyro_rad_s{};      ///< angular rate, rad/s, sensor frame
    Vec3d accel_m_s2{};      ///< specific force, m/s² (a level sensor at rest reads +9.81 on its up axis)
    Vec3d mag_ut{};          ///< magnetic field, µT (filters use its direction)
    std::uint8_t flags = 0;  ///< ImuSampleFlags

    [[nodiscard]] bool has_mag() const { return (flags & kImuNoMag) == 0; }
};

}  // namespace mocap
