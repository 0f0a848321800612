/* MPU9250 + AK8963 driver. Why it is shaped this way:
 * - the AK8963 sits behind the MPU's auxiliary I2C bus; slave 4 does the single register
 *   transactions of start-up (it has a DONE flag to poll), slave 0 then reads ST1..ST2
 *   continuously so that one SPI burst gets all nine axes of the same instant;
 * - slave 0 is slowed to every 10th internal sample (1 kHz / 10 = the AK8963's 100 Hz mode)
 *   so the auxiliary bus is not kept busy re-reading unchanged data;
 * - reading ST2 is part of the burst because the AK8963 only releases its data latch after
 *   ST2 was read. */
#include "sensor_node/mpu9250.h"

#include "mocap_wire/mw_common.h"

#define MPU9250_RESET_WAIT_US 100000u
#define AK8963_MODE_WAIT_US 10000u
#define I2C_SLV4_TIMEOUT_US 5000u
#define MAG_BURST_BYTES 8u /* ST1, HXL..HZH, ST2 */
#define SLV0_EVERY_NTH_SAMPLE 10u

static void wait_us(const mpu9250* dev, uint32_t us) {
    const uint64_t start = dev->bus.time_us(dev->bus.user);
    while (dev->bus.time_us(dev->bus.user) - start < us) {
    }
}

int mpu9250_write_reg(mpu9250* dev, uint8_t reg, uint8_t value) {
    const uint8_t tx[2] = {(uint8_t)(reg & 0x7Fu), value};
    uint8_t rx[2];
    return dev->bus.spi_transfer(dev->bus.user, tx, rx, sizeof tx) == 0 ? MPU9250_OK : MPU9250_ERR_SPI;
}

int mpu9250_read_regs(mpu9250* dev, uint8_t reg, uint8_t* out, size_t len) {
    uint8_t tx[32] = {0};
    uint8_t rx[32];
    if (len + 1u > sizeof tx) {
        return MPU9250_ERR_ARG;
    }
    tx[0] = (uint8_t)(reg | MPU9250_READ_FLAG);
    if (dev->bus.spi_transfer(dev->bus.user, tx, rx, len + 1u) != 0) {
        return MPU9250_ERR_SPI;
    }
    for (size_t i = 0; i < len; ++i) {
        out[i] = rx[i + 1u];
    }
    return MPU9250_OK;
}

/* One auxiliary-bus transaction through slave 4; reads return the byte in *value. */
static int slv4_transfer(mpu9250* dev, uint8_t ak_reg, int read, uint8_t* value) {
    int rc =
        mpu9250_write_reg(dev, MPU9250_I2C_SLV4_ADDR, (uint8_t)(AK8963_I2C_ADDR | (read ? MPU9250_I2C_SLV_READ : 0u)));
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV4_REG, ak_reg);
    }
    if (rc == MPU9250_OK && !read) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV4_DO, *value);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV4_CTRL, MPU9250_I2C_SLV_EN);
    }
    if (rc != MPU9250_OK) {
        return rc;
    }
    const uint64_t start = dev->bus.time_us(dev->bus.user);
    for (;;) {
        uint8_t status = 0;
        rc = mpu9250_read_regs(dev, MPU9250_I2C_MST_STATUS, &status, 1u);
        if (rc != MPU9250_OK) {
            return rc;
        }
        if (status & MPU9250_I2C_SLV4_NACK) {
            return MPU9250_ERR_I2C;
        }
        if (status & MPU9250_I2C_SLV4_DONE) {
            break;
        }
        if (dev->bus.time_us(dev->bus.user) - start > I2C_SLV4_TIMEOUT_US) {
            return MPU9250_ERR_I2C;
        }
    }
    return read ? mpu9250_read_regs(dev, MPU9250_I2C_SLV4_DI, value, 1u) : MPU9250_OK;
}

static int ak8963_write(mpu9250* dev, uint8_t reg, uint8_t value) {
    return slv4_transfer(dev, reg, 0, &value);
}

static int ak8963_read(mpu9250* dev, uint8_t reg, uint8_t* value) {
    return slv4_transfer(dev, reg, 1, value);
}

static int ak8963_init(mpu9250* dev) {
    uint8_t wia = 0;
    int rc = ak8963_write(dev, AK8963_CNTL2, AK8963_CNTL2_SRST);
    if (rc != MPU9250_OK) {
        return rc;
    }
    wait_us(dev, AK8963_MODE_WAIT_US);
    rc = ak8963_read(dev, AK8963_WIA, &wia);
    if (rc != MPU9250_OK) {
        return rc;
    }
    if (wia != AK8963_WIA_VALUE) {
        return MPU9250_ERR_MAG_ID;
    }
    /* The fuse ROM (ASA) is only readable in fuse-ROM mode; the datasheet requires power-down
     * between mode changes. */
    rc = ak8963_write(dev, AK8963_CNTL1, AK8963_CNTL1_FUSE_ROM);
    wait_us(dev, AK8963_MODE_WAIT_US);
    for (uint8_t i = 0; i < 3u && rc == MPU9250_OK; ++i) {
        rc = ak8963_read(dev, (uint8_t)(AK8963_ASAX + i), &dev->mag_asa[i]);
    }
    if (rc == MPU9250_OK) {
        rc = ak8963_write(dev, AK8963_CNTL1, AK8963_CNTL1_POWER_DOWN);
    }
    wait_us(dev, AK8963_MODE_WAIT_US);
    if (rc == MPU9250_OK) {
        rc = ak8963_write(dev, AK8963_CNTL1, AK8963_CNTL1_16BIT_100HZ);
    }
    wait_us(dev, AK8963_MODE_WAIT_US);
    /* Slave 0: read ST1..ST2 into EXT_SENS_DATA_00..07 every 10th sample. */
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV0_ADDR, AK8963_I2C_ADDR | MPU9250_I2C_SLV_READ);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV0_REG, AK8963_ST1);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV0_CTRL, MPU9250_I2C_SLV_EN | MAG_BURST_BYTES);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_SLV4_CTRL, SLV0_EVERY_NTH_SAMPLE - 1u);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_I2C_MST_DELAY_CTRL, MPU9250_I2C_SLV0_DLY_EN);
    }
    return rc;
}

int mpu9250_init(mpu9250* dev, const mpu9250_bus* bus, mw_accel_range accel_fs, mw_gyro_range gyro_fs,
                 uint8_t dlpf_cfg) {
    if (dev == NULL || bus == NULL || bus->spi_transfer == NULL || bus->time_us == NULL) {
        return MPU9250_ERR_ARG;
    }
    dev->bus = *bus;
    dev->who_am_i = 0;
    dev->mag_present = 0;
    dev->mag_asa[0] = dev->mag_asa[1] = dev->mag_asa[2] = 128u; /* neutral adjustment */

    int rc = mpu9250_write_reg(dev, MPU9250_PWR_MGMT_1, MPU9250_PWR_RESET);
    if (rc != MPU9250_OK) {
        return rc;
    }
    wait_us(dev, MPU9250_RESET_WAIT_US);
    rc = mpu9250_read_regs(dev, MPU9250_WHO_AM_I, &dev->who_am_i, 1u);
    if (rc != MPU9250_OK) {
        return rc;
    }
    if (dev->who_am_i != MPU9250_WHO_AM_I_9250 && dev->who_am_i != MPU9250_WHO_AM_I_9255) {
        return MPU9250_ERR_WHO_AM_I;
    }
    const uint8_t setup[][2] = {
        {MPU9250_PWR_MGMT_1, MPU9250_PWR_CLK_PLL},
        {MPU9250_PWR_MGMT_2, 0x00}, /* all axes on */
        {MPU9250_SMPLRT_DIV, 0x00}, /* 1 kHz internal rate; the node samples on SYNC */
        {MPU9250_USER_CTRL, MPU9250_USER_I2C_MST_EN | MPU9250_USER_I2C_IF_DIS | MPU9250_USER_I2C_MST_RST},
        {MPU9250_I2C_MST_CTRL, MPU9250_I2C_MST_P_NSR | MPU9250_I2C_MST_400KHZ},
    };
    for (size_t i = 0; i < sizeof setup / sizeof setup[0] && rc == MPU9250_OK; ++i) {
        rc = mpu9250_write_reg(dev, setup[i][0], setup[i][1]);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_set_ranges(dev, accel_fs, gyro_fs);
    }
    if (rc == MPU9250_OK) {
        rc = mpu9250_set_dlpf(dev, dlpf_cfg);
    }
    if (rc != MPU9250_OK) {
        return rc;
    }
    rc = ak8963_init(dev);
    if (rc == MPU9250_OK) {
        dev->mag_present = 1u;
    } else if (rc != MPU9250_ERR_SPI) {
        /* Accelerometer and gyroscope stay usable; stop the auxiliary reads. */
        (void)mpu9250_write_reg(dev, MPU9250_I2C_SLV0_CTRL, 0x00);
    }
    return rc;
}

int mpu9250_set_ranges(mpu9250* dev, mw_accel_range accel_fs, mw_gyro_range gyro_fs) {
    if ((unsigned)accel_fs > 3u || (unsigned)gyro_fs > 3u) {
        return MPU9250_ERR_ARG;
    }
    /* FCHOICE_B = 00 keeps the DLPF in the gyro path; self-test bits stay clear. */
    int rc = mpu9250_write_reg(dev, MPU9250_GYRO_CONFIG, (uint8_t)((unsigned)gyro_fs << 3));
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_ACCEL_CONFIG, (uint8_t)((unsigned)accel_fs << 3));
    }
    if (rc == MPU9250_OK) {
        dev->accel_fs = (uint8_t)accel_fs;
        dev->gyro_fs = (uint8_t)gyro_fs;
    }
    return rc;
}

int mpu9250_set_dlpf(mpu9250* dev, uint8_t dlpf_cfg) {
    if (dlpf_cfg > 6u) {
        return MPU9250_ERR_ARG;
    }
    int rc = mpu9250_write_reg(dev, MPU9250_CONFIG, dlpf_cfg);
    if (rc == MPU9250_OK) {
        rc = mpu9250_write_reg(dev, MPU9250_ACCEL_CONFIG2, dlpf_cfg); /* ACCEL_FCHOICE_B = 0 */
    }
    if (rc == MPU9250_OK) {
        dev->dlpf_cfg = dlpf_cfg;
    }
    return rc;
}

uint8_t mpu9250_dlpf_for_rate(uint16_t sample_rate_hz) {
    /* Larger of the gyro and accel -3 dB bandwidths per setting, Hz (register map table). */
    static const uint16_t bandwidth_hz[7] = {250, 219, 99, 45, 22, 11, 6};
    for (uint8_t cfg = 0; cfg < 7u; ++cfg) {
        if (2u * (uint32_t)bandwidth_hz[cfg] < sample_rate_hz) {
            return cfg;
        }
    }
    return 6u;
}

static int16_t be16(const uint8_t* p) {
    return (int16_t)(uint16_t)(((uint16_t)p[0] << 8) | p[1]);
}
static int16_t le16(const uint8_t* p) {
    return (int16_t)(uint16_t)(((uint16_t)p[1] << 8) | p[0]);
}

int mpu9250_read(mpu9250* dev, mpu9250_sample* out) {
    uint8_t raw[14u + MAG_BURST_BYTES];
    int rc = mpu9250_read_regs(dev, MPU9250_ACCEL_XOUT_H, raw, sizeof raw);
    if (rc != MPU9250_OK) {
        return rc;
    }
    uint8_t all = 0xFFu;
    for (size_t i = 0; i < 14u; ++i) {
        all &= raw[i];
    }
    if (all == 0xFFu) {
        return MPU9250_ERR_NO_SENSOR;
    }
    for (size_t i = 0; i < 3u; ++i) {
        out->accel[i] = be16(&raw[2u * i]);
        out->gyro[i] = be16(&raw[8u + 2u * i]);
    }
    out->temperature = be16(&raw[6]);
    out->mag_overflow = 0;
    if (dev->mag_present) {
        const uint8_t* m = &raw[14]; /* ST1, HXL, HXH, HYL, HYH, HZL, HZH, ST2 */
        const int16_t ak_raw[3] = {le16(&m[1]), le16(&m[3]), le16(&m[5])};
        out->mag_overflow = (m[7] & AK8963_ST2_HOFL) ? 1u : 0u;
        if (!out->mag_overflow && mw_mag_from_ak8963(ak_raw, dev->mag_asa, out->mag) == MW_OK) {
            return MPU9250_OK;
        }
    }
    out->mag[0] = out->mag[1] = out->mag[2] = MW_MAG_INVALID;
    return MPU9250_OK;
}
