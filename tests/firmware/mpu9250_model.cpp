#include "mpu9250_model.hpp"

namespace mocap::test {
namespace {
constexpr uint8_t kAkAddress = 0x0C;
constexpr uint8_t kI2cMstEn = 0x20;
constexpr uint8_t kSlvEn = 0x80;
constexpr uint8_t kSlvRead = 0x80;
constexpr uint8_t kSlv4Done = 0x40;
constexpr uint8_t kSlv4Nack = 0x10;
}  // namespace

void mpu9250_model::reset() {
    regs_.fill(0);
    regs_[0x6B] = 0x01;  // PWR_MGMT_1 default after reset
    regs_[0x75] = 0x71;  // WHO_AM_I
    ++resets;
}

bool mpu9250_model::i2c_master_on() const {
    return (regs_[0x6A] & kI2cMstEn) != 0;
}

uint8_t mpu9250_model::ak_read(uint8_t a) const {
    switch (a) {
        case 0x00:
            return 0x48;  // WIA
        case 0x02:
            return 0x01;  // ST1: data ready
        case 0x03:
            return static_cast<uint8_t>(mag_raw[0] & 0xFF);
        case 0x04:
            return static_cast<uint8_t>((mag_raw[0] >> 8) & 0xFF);
        case 0x05:
            return static_cast<uint8_t>(mag_raw[1] & 0xFF);
        case 0x06:
            return static_cast<uint8_t>((mag_raw[1] >> 8) & 0xFF);
        case 0x07:
            return static_cast<uint8_t>(mag_raw[2] & 0xFF);
        case 0x08:
            return static_cast<uint8_t>((mag_raw[2] >> 8) & 0xFF);
        case 0x09:
            return static_cast<uint8_t>(0x10 | (mag_overflow ? 0x08 : 0x00));  // ST2: BITM=16 bit
        case 0x10:
        case 0x11:
        case 0x12:
            return ak_[0x0A] == 0x0F ? mag_asa[a - 0x10] : 0x00;  // fuse ROM mode only
        default:
            return ak_[a & 0x1F];
    }
}

void mpu9250_model::ak_write(uint8_t a, uint8_t value) {
    if (a == 0x0B && (value & 0x01)) {
        ak_.fill(0);  // soft reset
        return;
    }
    ak_[a & 0x1F] = value;
}

bool mpu9250_model::ak_transfer(uint8_t addr_byte, uint8_t ak_address, uint8_t* value) {
    if (!mag_present || (addr_byte & 0x7F) != kAkAddress || !i2c_master_on()) {
        return false;
    }
    if (addr_byte & kSlvRead) {
        *value = ak_read(ak_address);
    } else {
        ak_write(ak_address, *value);
    }
    return true;
}

void mpu9250_model::write_reg(uint8_t a, uint8_t value) {
    writes.emplace_back(a, value);
    if (a == 0x6B && (value & 0x80)) {
        reset();
        return;
    }
    if (a == 0x6A) {
        regs_[a] = static_cast<uint8_t>(value & ~0x02);  // I2C_MST_RST self-clears
        return;
    }
    regs_[a] = value;
    if (a == 0x34 && (value & kSlvEn)) {  // I2C_SLV4_CTRL: run one transaction
        uint8_t data = regs_[0x33];
        const bool ok = ak_transfer(regs_[0x31], regs_[0x32], &data);
        if (ok && (regs_[0x31] & kSlvRead)) {
            regs_[0x35] = data;
        }
        regs_[0x36] = static_cast<uint8_t>(regs_[0x36] | (ok ? kSlv4Done : kSlv4Nack));
        regs_[0x34] = static_cast<uint8_t>(value & ~kSlvEn);  // EN clears when done
    }
}

uint8_t mpu9250_model::read_reg(uint8_t a) {
    auto be = [](int16_t v, bool high) {
        return static_cast<uint8_t>(high ? (static_cast<uint16_t>(v) >> 8) : (static_cast<uint16_t>(v) & 0xFF));
    };
    if (a >= 0x3B && a <= 0x40) {
        const int i = (a - 0x3B) / 2;
        return be(accel[i], ((a - 0x3B) % 2) == 0);
    }
    if (a == 0x41 || a == 0x42) {
        return be(temperature, a == 0x41);
    }
    if (a >= 0x43 && a <= 0x48) {
        const int i = (a - 0x43) / 2;
        return be(gyro[i], ((a - 0x43) % 2) == 0);
    }
    if (a >= 0x49 && a <= 0x60) {  // EXT_SENS_DATA, filled by slave 0
        const uint8_t ctrl = regs_[0x27];
        const unsigned len = ctrl & 0x0F;
        const unsigned index = a - 0x49u;
        if (!(ctrl & kSlvEn) || index >= len || !i2c_master_on() || !mag_present ||
            regs_[0x25] != (kAkAddress | kSlvRead)) {
            return 0;
        }
        return ak_read(static_cast<uint8_t>(regs_[0x26] + index));
    }
    if (a == 0x36) {  // I2C_MST_STATUS clears on read
        const uint8_t v = regs_[0x36];
        regs_[0x36] = 0;
        return v;
    }
    return regs_[a];
}

int mpu9250_model::transfer(const uint8_t* tx, uint8_t* rx, std::size_t len) {
    ++transfers;
    if (fail_spi) {
        return -1;
    }
    if (len == 0) {
        return 0;
    }
    if (!present) {
        for (std::size_t i = 0; i < len; ++i) {
            rx[i] = 0xFF;
        }
        return 0;
    }
    const bool read = (tx[0] & 0x80) != 0;
    const uint8_t start = tx[0] & 0x7F;
    rx[0] = 0;
    for (std::size_t i = 1; i < len; ++i) {
        const auto a = static_cast<uint8_t>((start + i - 1) & 0x7F);
        if (read) {
            rx[i] = read_reg(a);
        } else {
            rx[i] = 0;
            write_reg(a, tx[i]);
        }
    }
    return 0;
}

}  // namespace mocap::test
