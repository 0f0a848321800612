// scale_test.cpp — counts <-> SI for every MPU9250 range, saturation, and the AK8963 mapping.
#include <gtest/gtest.h>

#include <cmath>

#include "mocap_wire/mw_scale.h"

namespace {

constexpr double kG = 9.80665;
constexpr double kDegToRad = M_PI / 180.0;

TEST(WireScale, FullScaleMapsOntoTheInt16Range) {
    const double g_ranges[] = {2, 4, 8, 16};
    for (int r = 0; r < 4; ++r) {
        const auto range = static_cast<mw_accel_range>(r);
        EXPECT_EQ(mw_accel_range_g(range), g_ranges[r]);
        EXPECT_NEAR(mw_accel_m_s2_per_lsb(range), g_ranges[r] * kG / 32768.0, 1e-9);
    }
    const double dps_ranges[] = {250, 500, 1000, 2000};
    for (int r = 0; r < 4; ++r) {
        const auto range = static_cast<mw_gyro_range>(r);
        EXPECT_EQ(mw_gyro_range_dps(range), dps_ranges[r]);
        EXPECT_NEAR(mw_gyro_rad_s_per_lsb(range), dps_ranges[r] * kDegToRad / 32768.0, 1e-10);
    }
    // Datasheet sensitivities: 16384 LSB/g at 2 g, 2048 LSB/g at 16 g; 16.4 LSB/(deg/s) at 2000.
    EXPECT_NEAR(kG / mw_accel_m_s2_per_lsb(MW_ACCEL_2G), 16384.0, 1e-2);
    EXPECT_NEAR(kG / mw_accel_m_s2_per_lsb(MW_ACCEL_16G), 2048.0, 1e-3);
    EXPECT_NEAR(kDegToRad / mw_gyro_rad_s_per_lsb(MW_GYRO_2000DPS), 16.4, 0.02);
    EXPECT_EQ(mw_accel_range_g(static_cast<mw_accel_range>(4)), 0);
    EXPECT_EQ(mw_gyro_rad_s_per_lsb(static_cast<mw_gyro_range>(9)), 0.0f);
}

TEST(WireScale, OneGAndTwoHundredDegreesPerSecond) {
    const int16_t one_g[3] = {0, 0, 2048};
    float a[3];
    ASSERT_EQ(mw_accel_to_m_s2(one_g, MW_ACCEL_16G, a), MW_OK);
    EXPECT_NEAR(a[2], kG, 1e-5);
    const float rate[3] = {static_cast<float>(200.0 * kDegToRad), 0.0f, -0.5f};
    int16_t c[3];
    ASSERT_EQ(mw_gyro_from_rad_s(rate, MW_GYRO_2000DPS, c), 0);
    EXPECT_EQ(c[0], 3277);  // 200 / 2000 * 32768 = 3276.8
    float back[3];
    ASSERT_EQ(mw_gyro_to_rad_s(c, MW_GYRO_2000DPS, back), MW_OK);
    for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(back[i], rate[i], 0.5 * mw_gyro_rad_s_per_lsb(MW_GYRO_2000DPS));
}

TEST(WireScale, RoundTripIsWithinHalfAnLsbAndSaturationIsCounted) {
    for (int r = 0; r < 4; ++r) {
        const auto range = static_cast<mw_accel_range>(r);
        const float lsb = mw_accel_m_s2_per_lsb(range);
        for (int k = -32700; k <= 32700; k += 97) {
            const float v[3] = {k * lsb, (k + 0.49f) * lsb, (k - 0.49f) * lsb};
            int16_t c[3];
            ASSERT_EQ(mw_accel_from_m_s2(v, range, c), 0) << k;
            for (int i = 0; i < 3; ++i)
                EXPECT_EQ(c[i], k) << k << " axis " << i;
        }
        const float edge[3] = {32767.0f * lsb, -32768.0f * lsb, 32766.0f * lsb};
        int16_t c[3];
        EXPECT_EQ(mw_accel_from_m_s2(edge, range, c), 2);
        EXPECT_EQ(c[0], INT16_MAX);
        EXPECT_EQ(c[1], INT16_MIN);
        EXPECT_EQ(c[2], 32766);
    }
    const float big[3] = {1e6f, -1e6f, std::nanf("")};
    int16_t c[3];
    EXPECT_EQ(mw_accel_from_m_s2(big, MW_ACCEL_2G, c), 3);
    EXPECT_EQ(c[0], INT16_MAX);
    EXPECT_EQ(c[1], INT16_MIN);
    EXPECT_EQ(c[2], 0);
    EXPECT_EQ(mw_mag_from_ut(big, c), 3);
    EXPECT_EQ(c[0], MW_MAG_COUNTS_MAX);
    EXPECT_EQ(c[1], -MW_MAG_COUNTS_MAX);  // never the invalid marker
    EXPECT_EQ(mw_accel_from_m_s2(big, static_cast<mw_accel_range>(5), c), MW_ERR_ARGUMENT);
    EXPECT_EQ(mw_gyro_from_rad_s(nullptr, MW_GYRO_250DPS, c), MW_ERR_ARGUMENT);
}

TEST(WireScale, MagnetometerMicroteslaAndInvalidMarker) {
    const float earth[3] = {20.0f, -5.0f, -44.85f};
    int16_t c[3];
    ASSERT_EQ(mw_mag_from_ut(earth, c), 0);
    EXPECT_EQ(c[0], 133);  // 20 / 0.15 = 133.3
    EXPECT_EQ(c[2], -299);
    float ut[3];
    ASSERT_EQ(mw_mag_to_ut(c, ut), MW_OK);
    EXPECT_NEAR(ut[0], 19.95f, 1e-4f);
    const int16_t invalid[3] = {MW_MAG_INVALID, MW_MAG_INVALID, MW_MAG_INVALID};
    ut[0] = 123.0f;
    EXPECT_EQ(mw_mag_to_ut(invalid, ut), MW_ERR_RANGE);
    EXPECT_EQ(ut[0], 123.0f);
}

TEST(WireScale, Ak8963AxesAndSensitivityAdjustment) {
    // ASA = 128 means no adjustment; the axes swap x<->y and z flips.
    const int16_t raw[3] = {100, -200, 300};
    const uint8_t neutral[3] = {128, 128, 128};
    int16_t c[3];
    ASSERT_EQ(mw_mag_from_ak8963(raw, neutral, c), MW_OK);
    EXPECT_EQ(c[0], -200);
    EXPECT_EQ(c[1], 100);
    EXPECT_EQ(c[2], -300);
    // ASA = 176 -> x 1.1875; ASA = 0 -> x 0.5; ASA = 255 -> x 1.49609375.
    const uint8_t asa[3] = {176, 0, 255};
    ASSERT_EQ(mw_mag_from_ak8963(raw, asa, c), MW_OK);
    EXPECT_EQ(c[0], -100);  // y: -200 * 0.5
    EXPECT_EQ(c[1], 119);   // x: 100 * 1.1875 = 118.75 -> 119
    EXPECT_EQ(c[2], -449);  // z: -(300 * 1.49609375 = 448.83 -> 449)
    // Saturation at the AK8963 range, never the invalid marker.
    const int16_t huge[3] = {32000, -32000, -32000};
    const uint8_t gain[3] = {255, 255, 255};
    ASSERT_EQ(mw_mag_from_ak8963(huge, gain, c), MW_OK);
    EXPECT_EQ(c[0], -MW_MAG_COUNTS_MAX);
    EXPECT_EQ(c[1], MW_MAG_COUNTS_MAX);
    EXPECT_EQ(c[2], MW_MAG_COUNTS_MAX);
    const int16_t overflow[3] = {1, MW_MAG_INVALID, 3};
    EXPECT_EQ(mw_mag_from_ak8963(overflow, neutral, c), MW_ERR_RANGE);
    EXPECT_EQ(c[0], MW_MAG_INVALID);
    EXPECT_EQ(c[2], MW_MAG_INVALID);
}

}  // namespace
