/* MPU9250 driver over SPI, with the AK8963 magnetometer read through the MPU's own I2C
 * master (slave 0 copies the AK8963 data into EXT_SENS_DATA, so one SPI burst returns
 * all nine axes). Portable C99, no heap, no OS: the caller supplies the SPI transfer and a
 * microsecond clock (used only for the datasheet's start-up delays and I2C timeouts).
 *
 * Output frame: every axis, including the magnetometer, is given in the accelerometer /
 * gyroscope axes of the MPU9250 (the AK8963 has x and y swapped and z inverted relative to
 * them; mw_mag_from_ak8963() undoes that). Magnetometer counts have the factory sensitivity
 * adjustment (ASA) applied and are 0.15 uT per count (16-bit output).
 *
 * Cost: mpu9250_read() is one 23-byte SPI transfer; init takes ~150 ms (reset + AK8963). */
#ifndef MOCAP_SENSOR_NODE_MPU9250_H
#define MOCAP_SENSOR_NODE_MPU9250_H

#include <stddef.h>
#include <stdint.h>

#include "mocap_wire/mw_scale.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Register map (MPU-9250 register map rev 1.6, AK8963 datasheet). */
enum {
    MPU9250_SMPLRT_DIV = 0x19,
    MPU9250_CONFIG = 0x1A,
    MPU9250_GYRO_CONFIG = 0x1B,
    MPU9250_ACCEL_CONFIG = 0x1C,
    MPU9250_ACCEL_CONFIG2 = 0x1D,
    MPU9250_I2C_MST_CTRL = 0x24,
    MPU9250_I2C_SLV0_ADDR = 0x25,
    MPU9250_I2C_SLV0_REG = 0x26,
    MPU9250_I2C_SLV0_CTRL = 0x27,
    MPU9250_I2C_SLV4_ADDR = 0x31,
    MPU9250_I2C_SLV4_REG = 0x32,
    MPU9250_I2C_SLV4_DO = 0x33,
    MPU9250_I2C_SLV4_CTRL = 0x34,
    MPU9250_I2C_SLV4_DI = 0x35,
    MPU9250_I2C_MST_STATUS = 0x36,
    MPU9250_ACCEL_XOUT_H = 0x3B,
    MPU9250_TEMP_OUT_H = 0x41,
    MPU9250_GYRO_XOUT_H = 0x43,
    MPU9250_EXT_SENS_DATA_00 = 0x49,
    MPU9250_I2C_MST_DELAY_CTRL = 0x67,
    MPU9250_USER_CTRL = 0x6A,
    MPU9250_PWR_MGMT_1 = 0x6B,
    MPU9250_PWR_MGMT_2 = 0x6C,
    MPU9250_WHO_AM_I = 0x75,

    MPU9250_READ_FLAG = 0x80,
    MPU9250_WHO_AM_I_9250 = 0x71,
    MPU9250_WHO_AM_I_9255 = 0x73,
    MPU9250_PWR_RESET = 0x80,
    MPU9250_PWR_CLK_PLL = 0x01,
    MPU9250_USER_I2C_MST_EN = 0x20,
    MPU9250_USER_I2C_IF_DIS = 0x10, /* SPI only: disables the primary I2C interface */
    MPU9250_USER_I2C_MST_RST = 0x02,
    MPU9250_I2C_MST_400KHZ = 0x0D,
    MPU9250_I2C_MST_P_NSR = 0x10,
    MPU9250_I2C_SLV_EN = 0x80,
    MPU9250_I2C_SLV_READ = 0x80,
    MPU9250_I2C_SLV4_DONE = 0x40,
    MPU9250_I2C_SLV4_NACK = 0x10,
    MPU9250_I2C_SLV0_NACK = 0x01,
    MPU9250_I2C_SLV0_DLY_EN = 0x01,

    AK8963_I2C_ADDR = 0x0C,
    AK8963_WIA = 0x00,
    AK8963_WIA_VALUE = 0x48,
    AK8963_ST1 = 0x02,
    AK8963_HXL = 0x03,
    AK8963_ST2 = 0x09,
    AK8963_CNTL1 = 0x0A,
    AK8963_CNTL2 = 0x0B,
    AK8963_ASAX = 0x10,
    AK8963_ST2_HOFL = 0x08,
    AK8963_CNTL1_POWER_DOWN = 0x00,
    AK8963_CNTL1_FUSE_ROM = 0x0F,
    AK8963_CNTL1_16BIT_100HZ = 0x16,
    AK8963_CNTL2_SRST = 0x01
};

/* Full-scale selections are the wire library's mw_accel_range / mw_gyro_range, whose values
 * are the GYRO_CONFIG / ACCEL_CONFIG bits [4:3] fields. */

typedef enum {
    MPU9250_OK = 0,
    MPU9250_ERR_SPI = -1,      /* the bus transfer itself failed */
    MPU9250_ERR_WHO_AM_I = -2, /* no MPU9250/9255 answered */
    MPU9250_ERR_I2C = -3,      /* AK8963 transaction NACKed or timed out */
    MPU9250_ERR_MAG_ID = -4,   /* AK8963 answered with a wrong WIA */
    MPU9250_ERR_ARG = -5,
    MPU9250_ERR_NO_SENSOR = -6 /* a sample burst read all 0xFF: nothing drives MISO */
} mpu9250_status;

/* The bus: caller-owned, must outlive the driver. spi_transfer runs one chip-select-framed,
 * full-duplex transfer of len bytes (rx may alias nothing; both buffers are len bytes) and
 * returns 0 on success. time_us is a monotonic microsecond clock. */
typedef struct {
    void* user;
    int (*spi_transfer)(void* user, const uint8_t* tx, uint8_t* rx, size_t len);
    uint64_t (*time_us)(void* user);
} mpu9250_bus;

/* One sample in counts, MPU9250 axes (see top). mag[] is all MW_MAG_INVALID when there is no
 * magnetometer or the AK8963 reported overflow (HOFL; then mag_overflow is 1). */
typedef struct {
    int16_t accel[3];
    int16_t gyro[3];
    int16_t mag[3];
    int16_t temperature;
    uint8_t mag_overflow;
} mpu9250_sample;

/* Driver state; zero-initialise or let mpu9250_init() fill it. */
typedef struct {
    mpu9250_bus bus;
    uint8_t who_am_i;
    uint8_t mag_asa[3];  /* AK8963 factory sensitivity adjustment, 0..255 */
    uint8_t mag_present; /* AK8963 found and running; mag[] is zero otherwise */
    uint8_t accel_fs;    /* mw_accel_range */
    uint8_t gyro_fs;     /* mw_gyro_range */
    uint8_t dlpf_cfg;    /* CONFIG.DLPF_CFG and ACCEL_CONFIG2.A_DLPFCFG, 0..6 */
} mpu9250;

/* Resets the chip, checks WHO_AM_I, selects the PLL clock, sets ranges and low-pass filter,
 * then brings up the AK8963 through slave 4 (reset, WIA check, fuse ROM ASA read, 16-bit
 * 100 Hz continuous mode) and starts slave 0 copying ST1..ST2 into EXT_SENS_DATA.
 * Returns MPU9250_OK, or MPU9250_ERR_I2C / MPU9250_ERR_MAG_ID when only the magnetometer
 * failed (the accelerometer and gyroscope are then usable and mag_present is 0), or a
 * fatal error (SPI, WHO_AM_I). */
int mpu9250_init(mpu9250* dev, const mpu9250_bus* bus, mw_accel_range accel_fs, mw_gyro_range gyro_fs,
                 uint8_t dlpf_cfg);

/* Changes the full-scale ranges (two register writes). */
int mpu9250_set_ranges(mpu9250* dev, mw_accel_range accel_fs, mw_gyro_range gyro_fs);

/* Low-pass filter for gyroscope and accelerometer, 0..6 (0 = 250/218 Hz ... 6 = 5 Hz). */
int mpu9250_set_dlpf(mpu9250* dev, uint8_t dlpf_cfg);

/* The widest DLPF setting whose bandwidth stays under half of sample_rate_hz. */
uint8_t mpu9250_dlpf_for_rate(uint16_t sample_rate_hz);

/* Reads one nine-axis sample (one SPI burst from ACCEL_XOUT_H through EXT_SENS_DATA_07).
 * MPU9250_ERR_NO_SENSOR when the accelerometer, temperature and gyroscope bytes are all 0xFF:
 * MISO floats high with no sensor driving it, and -1 counts would pass for a sample. */
int mpu9250_read(mpu9250* dev, mpu9250_sample* out);

/* Register helpers, exposed for the node core and tests. */
int mpu9250_write_reg(mpu9250* dev, uint8_t reg, uint8_t value);
int mpu9250_read_regs(mpu9250* dev, uint8_t reg, uint8_t* out, size_t len);

#ifdef __cplusplus
}
#endif

#endif
