// Register-level model of an MPU9250 with its AK8963, behind a fake SPI bus. It answers the
// way the datasheets describe: auto-incrementing burst reads, reset to register defaults, the
// auxiliary I2C master's slave 4 transactions (DONE/NACK in I2C_MST_STATUS, cleared on read)
// and slave 0 copying AK8963 registers into EXT_SENS_DATA; the AK8963's fuse ROM is readable
// only in fuse-ROM mode. Tests set the counts it returns and inspect what was written.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace mocap::test {

class mpu9250_model {
public:
    // Knobs.
    bool present = true;      // false: MISO floats high (every byte reads 0xFF)
    bool mag_present = true;  // false: the AK8963 NACKs
    std::array<int16_t, 3> accel{};
    std::array<int16_t, 3> gyro{};
    int16_t temperature = 0;
    std::array<int16_t, 3> mag_raw{};  // AK8963 axes, before sensitivity adjustment
    std::array<uint8_t, 3> mag_asa{128, 128, 128};
    bool mag_overflow = false;
    bool fail_spi = false;  // the transfer itself reports an error

    // Observations.
    std::vector<std::pair<uint8_t, uint8_t>> writes;  // every MPU register write, in order
    int resets = 0;
    int transfers = 0;

    mpu9250_model() { reset(); }

    uint8_t reg(uint8_t address) const { return regs_[address & 0x7F]; }
    uint8_t ak_reg(uint8_t address) const { return ak_[address & 0x1F]; }

    int transfer(const uint8_t* tx, uint8_t* rx, std::size_t len);

private:
    void reset();
    void write_reg(uint8_t address, uint8_t value);
    uint8_t read_reg(uint8_t address);
    bool i2c_master_on() const;
    bool ak_transfer(uint8_t addr_byte, uint8_t ak_address, uint8_t* value);
    uint8_t ak_read(uint8_t ak_address) const;
    void ak_write(uint8_t ak_address, uint8_t value);

    std::array<uint8_t, 128> regs_{};
    std::array<uint8_t, 32> ak_{};
};

}  // namespace mocap::test
