// marg.hpp — what the orientation filters share about one sample's accelerometer and
// magnetometer (MARG: magnetic, angular rate and gravity): which readings are usable, and the
// closed-form attitude they give. Used by the default filter, Madgwick, Mahony and the
// particle filter, so that no filter includes a sibling filter to borrow them.
//
// Frame: ENU earth (x east, y north, z up); q_enu_sensor rotates sensor-frame vectors into it.
// Pure functions, thread-safe, no allocation. Cost: read_marg a few ns; attitude_from_accel_mag
// about one TRIAD solve (~50 ns, attitude_solver.hpp).
#pragma once

#include "core/imu_sample.hpp"
#include "math/quaternion.hpp"

namespace mocap::filter {

/// One sample's accelerometer and magnetometer with their usability: non-zero and finite,
/// and for the magnetometer also present (no kImuNoMag flag).
struct MargReading {
    math::Vec3 accel_m_s2 = math::Vec3::Zero();
    math::Vec3 mag_ut = math::Vec3::Zero();
    bool accel_ok = false;
    bool mag_ok = false;
};
MargReading read_marg(const ImuSample& sample);

/// Closed-form attitude q_enu_sensor from one specific-force reading (a level sensor at
/// rest reads +9.81 on its up axis) and, if use_mag, one magnetometer reading: gravity fixes
/// the inclination exactly, the magnetometer's component perpendicular to it fixes the
/// heading (TRIAD with the accelerometer as primary vector). Without the magnetometer (or
/// when it is parallel to gravity) the heading is zero. accel must be non-zero.
math::Quat attitude_from_accel_mag(const math::Vec3& accel_m_s2, const math::Vec3& mag_ut, bool use_mag);

/// Shortest rotation taking the unit vector u onto earth z (no rotation about z); a u that
/// points straight down gives 180° about a horizontal axis.
math::Quat tilt_to_vertical(const math::Vec3& u);

}  // namespace mocap::filter
