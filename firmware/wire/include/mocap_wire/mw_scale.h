/*
 * mw_scale.h — sensor ranges and the conversion between MPU9250/AK8963 counts and SI units.
 *
 * One definition of the scale factors so that the firmware, the simulator and the daemon agree
 * bit for bit. Full-scale ranges map onto the int16 range exactly: one LSB is range / 32768
 * (the datasheet's rounded sensitivities, e.g. 131 and 16.4 LSB/(deg/s), differ from these by
 * < 0.1 %, far inside the part's +-3 % tolerance).
 *
 * Axes: all three vectors are sent in the MPU9250 accelerometer/gyroscope axes (right-handed).
 * The AK8963 inside the MPU9250 has different axes; mw_mag_from_ak8963() converts them.
 * The accelerometer measures specific force: a level node at rest reads about +1 g on +z.
 *
 * Units: m/s^2 (standard gravity 9.80665 m/s^2 per g), rad/s, uT. Float arithmetic only in the
 * conversion functions (soft-float on Cortex-M3: call them only where the cost is acceptable).
 * Cost: O(1), no state, reentrant.
 */
#ifndef MOCAP_WIRE_MW_SCALE_H
#define MOCAP_WIRE_MW_SCALE_H

#include <stdint.h>

#include "mocap_wire/mw_common.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Standard gravity, m/s^2 per g. */
#define MW_STANDARD_GRAVITY_M_S2 9.80665f

/** AK8963 sensitivity in 16-bit output mode, uT per LSB. */
#define MW_MAG_UT_PER_LSB 0.15f

/** Largest magnitude the AK8963 reports in 16-bit mode (datasheet: -32760..32760). */
#define MW_MAG_COUNTS_MAX 32760

/**
 * Marker for "no valid magnetometer reading this sample" (AK8963 overflow HOFL, data not ready,
 * or no magnetometer): all three axes set to this value. The AK8963 never outputs it.
 */
#define MW_MAG_INVALID INT16_MIN

/** Accelerometer full-scale range; the values equal the MPU9250 ACCEL_FS_SEL field. */
typedef enum mw_accel_range { MW_ACCEL_2G = 0, MW_ACCEL_4G = 1, MW_ACCEL_8G = 2, MW_ACCEL_16G = 3 } mw_accel_range;

/** Gyroscope full-scale range; the values equal the MPU9250 GYRO_FS_SEL field. */
typedef enum mw_gyro_range {
    MW_GYRO_250DPS = 0,
    MW_GYRO_500DPS = 1,
    MW_GYRO_1000DPS = 2,
    MW_GYRO_2000DPS = 3
} mw_gyro_range;

/** Full scale in g (2, 4, 8, 16); 0 for an invalid range. */
uint16_t mw_accel_range_g(mw_accel_range range);

/** Full scale in deg/s (250, 500, 1000, 2000); 0 for an invalid range. */
uint16_t mw_gyro_range_dps(mw_gyro_range range);

/** m/s^2 per LSB for the range (range_g * 9.80665 / 32768); 0 for an invalid range. */
float mw_accel_m_s2_per_lsb(mw_accel_range range);

/** rad/s per LSB for the range (range_dps * pi / 180 / 32768); 0 for an invalid range. */
float mw_gyro_rad_s_per_lsb(mw_gyro_range range);

/** counts -> m/s^2. Returns MW_OK, or MW_ERR_ARGUMENT for NULL pointers / an invalid range. */
int mw_accel_to_m_s2(const int16_t counts[3], mw_accel_range range, float accel_m_s2[3]);

/** counts -> rad/s. Returns MW_OK, or MW_ERR_ARGUMENT for NULL pointers / an invalid range. */
int mw_gyro_to_rad_s(const int16_t counts[3], mw_gyro_range range, float gyro_rad_s[3]);

/**
 * counts -> uT. Returns MW_OK; MW_ERR_RANGE if the reading is marked invalid (any axis equals
 * MW_MAG_INVALID; mag_ut is then left untouched); MW_ERR_ARGUMENT for NULL pointers.
 */
int mw_mag_to_ut(const int16_t counts[3], float mag_ut[3]);

/**
 * SI -> counts, rounding to nearest and saturating at the int16 limits (-32768..32767).
 * Used by the simulator and by tests. Returns the number of saturated axes (0..3), or
 * MW_ERR_ARGUMENT for NULL pointers / an invalid range. NaN inputs become 0 and count as saturated.
 */
int mw_accel_from_m_s2(const float accel_m_s2[3], mw_accel_range range, int16_t counts[3]);
int mw_gyro_from_rad_s(const float gyro_rad_s[3], mw_gyro_range range, int16_t counts[3]);

/** uT -> counts, saturating at +-MW_MAG_COUNTS_MAX (so the result is never MW_MAG_INVALID). */
int mw_mag_from_ut(const float mag_ut[3], int16_t counts[3]);

/**
 * AK8963 raw 16-bit reading -> magnetometer counts in the MPU9250 accel/gyro axes, with the
 * factory sensitivity adjustment applied (ASAX..ASAZ from fuse ROM):
 *   adjusted_i = round(raw_i * (asa_i + 128) / 256), then x = adj_y, y = adj_x, z = -adj_z,
 * saturated at +-MW_MAG_COUNTS_MAX. Integer only. Returns MW_OK or MW_ERR_ARGUMENT (NULL).
 * If any raw axis is MW_MAG_INVALID, all outputs are set to MW_MAG_INVALID and MW_ERR_RANGE is
 * returned.
 */
int mw_mag_from_ak8963(const int16_t ak_raw[3], const uint8_t asa[3], int16_t counts[3]);

#ifdef __cplusplus
}
#endif

#endif /* MOCAP_WIRE_MW_SCALE_H */
