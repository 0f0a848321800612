/*
 * mw_scale.c — counts <-> SI. One LSB is full scale / 32768 so that encode and decode are exact
 * inverses up to rounding, in the firmware, the simulator and the daemon alike.
 */
#include "mocap_wire/mw_scale.h"

#include <stddef.h>

#include "mocap_wire/mw_common.h"

#define MW_PI_F 3.14159265358979f
#define MW_INT16_SPAN 32768.0f

uint16_t mw_accel_range_g(mw_accel_range range) {
    static const uint16_t g[4] = {2u, 4u, 8u, 16u};
    return (unsigned)range < 4u ? g[range] : 0u;
}

uint16_t mw_gyro_range_dps(mw_gyro_range range) {
    static const uint16_t dps[4] = {250u, 500u, 1000u, 2000u};
    return (unsigned)range < 4u ? dps[range] : 0u;
}

float mw_accel_m_s2_per_lsb(mw_accel_range range) {
    return (float)mw_accel_range_g(range) * MW_STANDARD_GRAVITY_M_S2 / MW_INT16_SPAN;
}

float mw_gyro_rad_s_per_lsb(mw_gyro_range range) {
    return (float)mw_gyro_range_dps(range) * (MW_PI_F / 180.0f) / MW_INT16_SPAN;
}

static void counts_to_si(const int16_t counts[3], float scale, float out[3]) {
    for (int i = 0; i < 3; ++i)
        out[i] = (float)counts[i] * scale;
}

/* Round to nearest (half away from zero) and clamp to [lo, hi]; returns the clamped axes. */
static int si_to_counts(const float in[3], float lsb, int32_t lo, int32_t hi, int16_t out[3]) {
    int saturated = 0;
    for (int i = 0; i < 3; ++i) {
        const float v = in[i] / lsb;
        int32_t c;
        if (v != v) { /* NaN */
            c = 0;
            ++saturated;
        } else if (v >= (float)hi) {
            c = hi;
            ++saturated;
        } else if (v <= (float)lo) {
            c = lo;
            ++saturated;
        } else {
            c = (int32_t)(v < 0.0f ? v - 0.5f : v + 0.5f);
        }
        out[i] = (int16_t)c;
    }
    return saturated;
}

int mw_accel_to_m_s2(const int16_t counts[3], mw_accel_range range, float accel_m_s2[3]) {
    const float lsb = mw_accel_m_s2_per_lsb(range);
    if (counts == NULL || accel_m_s2 == NULL || lsb == 0.0f) return MW_ERR_ARGUMENT;
    counts_to_si(counts, lsb, accel_m_s2);
    return MW_OK;
}

int mw_gyro_to_rad_s(const int16_t counts[3], mw_gyro_range range, float gyro_rad_s[3]) {
    const float lsb = mw_gyro_rad_s_per_lsb(range);
    if (counts == NULL || gyro_rad_s == NULL || lsb == 0.0f) return MW_ERR_ARGUMENT;
    counts_to_si(counts, lsb, gyro_rad_s);
    return MW_OK;
}

int mw_mag_to_ut(const int16_t counts[3], float mag_ut[3]) {
    if (counts == NULL || mag_ut == NULL) return MW_ERR_ARGUMENT;
    for (int i = 0; i < 3; ++i) {
        if (counts[i] == MW_MAG_INVALID) return MW_ERR_RANGE;
    }
    counts_to_si(counts, MW_MAG_UT_PER_LSB, mag_ut);
    return MW_OK;
}

int mw_accel_from_m_s2(const float accel_m_s2[3], mw_accel_range range, int16_t counts[3]) {
    const float lsb = mw_accel_m_s2_per_lsb(range);
    if (accel_m_s2 == NULL || counts == NULL || lsb == 0.0f) return MW_ERR_ARGUMENT;
    return si_to_counts(accel_m_s2, lsb, INT16_MIN, INT16_MAX, counts);
}

int mw_gyro_from_rad_s(const float gyro_rad_s[3], mw_gyro_range range, int16_t counts[3]) {
    const float lsb = mw_gyro_rad_s_per_lsb(range);
    if (gyro_rad_s == NULL || counts == NULL || lsb == 0.0f) return MW_ERR_ARGUMENT;
    return si_to_counts(gyro_rad_s, lsb, INT16_MIN, INT16_MAX, counts);
}

int mw_mag_from_ut(const float mag_ut[3], int16_t counts[3]) {
    if (mag_ut == NULL || counts == NULL) return MW_ERR_ARGUMENT;
    return si_to_counts(mag_ut, MW_MAG_UT_PER_LSB, -MW_MAG_COUNTS_MAX, MW_MAG_COUNTS_MAX, counts);
}

static int16_t clamp_mag(int32_t v) {
    if (v > MW_MAG_COUNTS_MAX) return MW_MAG_COUNTS_MAX;
    if (v < -MW_MAG_COUNTS_MAX) return -MW_MAG_COUNTS_MAX;
    return (int16_t)v;
}

/* Sensitivity adjustment (AK8963 datasheet 8.3.11): Hadj = H * ((ASA - 128) * 0.5 / 128 + 1)
 * = H * (ASA + 128) / 256, rounded half away from zero in integers. */
static int32_t ak8963_adjust(int16_t raw, uint8_t asa) {
    const int32_t num = (int32_t)raw * ((int32_t)asa + 128);
    return num >= 0 ? (num + 128) / 256 : -((-num + 128) / 256);
}

int mw_mag_from_ak8963(const int16_t ak_raw[3], const uint8_t asa[3], int16_t counts[3]) {
    if (ak_raw == NULL || asa == NULL || counts == NULL) return MW_ERR_ARGUMENT;
    if (ak_raw[0] == MW_MAG_INVALID || ak_raw[1] == MW_MAG_INVALID || ak_raw[2] == MW_MAG_INVALID) {
        counts[0] = counts[1] = counts[2] = MW_MAG_INVALID;
        return MW_ERR_RANGE;
    }
    /* MPU9250 datasheet, section 9.1: the AK8963's x is the accelerometer's y, its y the
     * accelerometer's x, and its z points the other way. */
    const int32_t x = ak8963_adjust(ak_raw[1], asa[1]);
    const int32_t y = ak8963_adjust(ak_raw[0], asa[0]);
    const int32_t z = -ak8963_adjust(ak_raw[2], asa[2]);
    counts[0] = clamp_mag(x);
    counts[1] = clamp_mag(y);
    counts[2] = clamp_mag(z);
    return MW_OK;
}
