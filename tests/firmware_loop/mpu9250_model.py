"""MPU-9250 with its AK8963 magnetometer, as an SPI slave on virtual time.

Written from the MPU-9250 Register Map rev 1.6 and Product Specification rev 1.1 and the
AK8963 datasheet: every register resets to 0 except PWR_MGMT_1 (0x01) and WHO_AM_I (0x71);
PWR_MGMT_1.H_RESET (bit 7) restores them; SPI mode 0 or 3, first byte = register address
with bit 7 set for a read, then auto-increment; SCLK at most 1 MHz, 20 MHz only for reading
the sensor and interrupt registers (spec §7.5); sensitivities 16384/8192/4096/2048 LSB/g
(ACCEL_FS_SEL 0..3) and 131/65.5/32.8/16.4 LSB/(deg/s) (GYRO_FS_SEL 0..3); temperature
333.87 LSB/degC around 21 degC; data big-endian.
Auxiliary I2C master (register map §4.12-4.21): slave 4 runs one transaction when
I2C_SLV4_CTRL.EN is written (EN clears, I2C_MST_STATUS.SLV4_DONE bit 6 or SLV4_NACK bit 4
sets; this model clears the status bits when I2C_MST_STATUS is read); slave 0 copies
I2C_SLV0_CTRL[3:0] bytes from the device register I2C_SLV0_REG into EXT_SENS_DATA_00.. at
the 1 kHz internal sample rate, every (1 + I2C_MST_DLY) samples when I2C_MST_DELAY_CTRL bit 0
is set; nothing runs without USER_CTRL.I2C_MST_EN. One I2C transaction takes I2C_XFER_US at
400 kHz.
AK8963 (datasheet §8): WIA 0x48; CNTL1 MODE 0 power-down, 1 single, 2/6 continuous 8/100 Hz,
0xF fuse ROM (ASA readable only then), BIT (bit 4) 16-bit output at 0.15 uT/LSB; ST1.DRDY
until ST2 is read; ST2.HOFL when |X|+|Y|+|Z| exceeds 4912 uT; output H = true /
(0.15 * ((ASA - 128) * 0.5 / 128 + 1)). Axes (MPU-9250 spec §9.1): the AK8963's x is the
MPU's y, its y the MPU's x, its z the MPU's -z.

The motion is constant (a `Motion` of specific force in g, rate in deg/s and field in uT,
MPU axes); for fault tests `who_am_i` can be set to a wrong value and `answering` cleared
(MISO then floats high: every byte reads 0xFF, as on the breakout with its pull-up).
"""

from dataclasses import dataclass

from virtual_clock import ticks_from_us

ACCEL_LSB_PER_G = (16384, 8192, 4096, 2048)
GYRO_LSB_PER_DPS = (131.0, 65.5, 32.8, 16.4)
I2C_XFER_US = 100
AK8963_ADDR = 0x0C
SENSOR_REGS = range(0x3A, 0x61)  # INT_STATUS through EXT_SENS_DATA_23


@dataclass
class Motion:
    accel_g: tuple = (0.0, 0.0, 1.0)
    gyro_dps: tuple = (0.0, 0.0, 0.0)
    mag_ut: tuple = (20.0, 0.0, -40.0)
    temp_c: float = 25.0


def _int16(v):
    return max(-32768, min(32767, int(round(v))))


class Ak8963:
    def __init__(self, clock, motion, asa):
        self.clock, self.motion, self.asa = clock, motion, asa
        self.reset()

    def reset(self):
        self.cntl1 = 0
        self.data_read = True
        self.mode_since = self.clock.ticks

    def _measure(self):
        m = self.motion.mag_ut
        ak = (m[1], m[0], -m[2])
        h = []
        for axis, asa in zip(ak, self.asa):
            h.append(_int16(axis / (0.15 * ((asa - 128) * 0.5 / 128 + 1))))
        hofl = sum(abs(v) for v in ak) > 4912
        return h, hofl

    def _drdy(self):
        mode = self.cntl1 & 0xF
        if mode in (2, 6):
            period = ticks_from_us(125000 if mode == 2 else 10000)
            return not self.data_read or self.clock.ticks - self.mode_since >= period
        return False

    def read(self, reg):
        mode = self.cntl1 & 0xF
        if reg == 0x00:
            return 0x48
        if reg == 0x01:
            return 0x9A
        if reg == 0x02:
            return 1 if self._drdy() else 0
        if 0x03 <= reg <= 0x08:
            if mode not in (1, 2, 6) and self.data_read:
                return 0
            h, _ = self._measure()
            v = h[(reg - 3) // 2] & 0xFFFF
            return v & 0xFF if reg % 2 == 1 else v >> 8
        if reg == 0x09:
            _, hofl = self._measure()
            self.data_read = True
            self.mode_since = self.clock.ticks
            return (0x08 if hofl else 0) | (self.cntl1 & 0x10)
        if reg == 0x0A:
            return self.cntl1
        if 0x10 <= reg <= 0x12:
            return self.asa[reg - 0x10] if mode == 0xF else 0
        return 0

    def write(self, reg, value):
        if reg == 0x0A:
            self.cntl1 = value & 0x1F
            self.mode_since = self.clock.ticks
            self.data_read = False
        elif reg == 0x0B and value & 1:
            self.reset()


class Mpu9250:
    def __init__(self, clock, motion=None, asa=(176, 177, 165), who_am_i=0x71):
        self.clock = clock
        self.motion = motion or Motion()
        self.who = who_am_i
        self.ak = Ak8963(clock, self.motion, asa)
        self.violations = []
        self.transactions = 0
        self.selected = False
        self.answering = True  # False: unpowered or cut off, nothing drives MISO (reads 0xFF)
        self.reset()

    def reset(self):
        self.regs = [0] * 128
        self.regs[0x6B] = 0x01
        self.slv4_done_at = None
        self.last_slv0_sample = None
        self.ak_present = True

    # --- SPI side ---
    def chip_select(self, level):
        """nCS from the GPIO pin: 0 starts a transaction, 1 (or undriven) ends it."""
        selected = level == 0
        if selected and not self.selected:
            self.transactions += 1
            self._advance()
            self.addr = None
            self.snapshot = self._sensor_bytes()
        self.selected = selected

    def exchange(self, byte, cpol, cpha, sck_hz):
        if not self.selected or not self.answering:
            return 0xFF
        if cpol != cpha:
            self.violations.append(f"SPI mode {2 * cpol + cpha} (the MPU-9250 takes mode 0 or 3)")
        if self.addr is None:
            self.addr, self.reading = byte & 0x7F, bool(byte & 0x80)
            fast_ok = self.reading and self.addr in SENSOR_REGS
            if sck_hz > (20_000_000 if fast_ok else 1_000_000):
                self.violations.append(f"SCLK {sck_hz} Hz for register 0x{self.addr:02X}")
            return 0
        reg = self.addr
        self.addr = (self.addr + 1) & 0x7F
        if self.reading:
            return self._read(reg)
        self._write(reg, byte)
        return 0

    # --- registers ---
    def _sensor_bytes(self):
        m = self.motion
        afs = (self.regs[0x1C] >> 3) & 3
        gfs = (self.regs[0x1B] >> 3) & 3
        pm2 = self.regs[0x6C]
        accel = [0 if pm2 & (0x20 >> i) else _int16(m.accel_g[i] * ACCEL_LSB_PER_G[afs]) for i in range(3)]
        gyro = [0 if pm2 & (0x04 >> i) else _int16(m.gyro_dps[i] * GYRO_LSB_PER_DPS[gfs]) for i in range(3)]
        temp = _int16((m.temp_c - 21.0) * 333.87)
        out = {}
        for k, v in enumerate(accel + [temp] + gyro):
            out[0x3B + 2 * k] = (v >> 8) & 0xFF
            out[0x3C + 2 * k] = v & 0xFF
        return out

    def _read(self, reg):
        if reg == 0x75:
            return self.who
        if reg in self.snapshot and not self.regs[0x6B] & 0x40:
            return self.snapshot[reg]
        value = self.regs[reg]
        if reg == 0x36:
            self._advance()
            value = self.regs[0x36]
            self.regs[0x36] = 0  # status bits clear when read
        return value

    def _write(self, reg, value):
        if reg == 0x6B and value & 0x80:
            self.reset()
            self.ak.reset()
            return
        if reg == 0x6A:
            value &= ~0x02  # I2C_MST_RST self-clears
        self.regs[reg] = value
        if reg == 0x34 and value & 0x80 and self.regs[0x6A] & 0x20:
            self.slv4_done_at = self.clock.ticks + ticks_from_us(I2C_XFER_US)

    def _advance(self):
        """Runs the I2C master up to now: a finished slave-4 transaction, slave-0 copies."""
        now = self.clock.ticks
        if self.slv4_done_at is not None and now >= self.slv4_done_at:
            self.slv4_done_at = None
            addr = self.regs[0x31]
            ok = (addr & 0x7F) == AK8963_ADDR and self.ak_present
            if ok and addr & 0x80:
                self.regs[0x35] = self.ak.read(self.regs[0x32])
            elif ok:
                self.ak.write(self.regs[0x32], self.regs[0x33])
            self.regs[0x36] |= 0x40 if ok else 0x10
            self.regs[0x34] &= ~0x80
        ctrl = self.regs[0x27]
        if not (self.regs[0x6A] & 0x20 and ctrl & 0x80):
            return
        sample = now // ticks_from_us(1000)
        every = (self.regs[0x34] & 0x1F) + 1 if self.regs[0x67] & 1 else 1
        latest = sample - sample % every
        if self.last_slv0_sample == latest:
            return
        self.last_slv0_sample = latest
        addr = self.regs[0x25]
        if (addr & 0x7F) != AK8963_ADDR or not addr & 0x80 or not self.ak_present:
            self.regs[0x36] |= 0x01  # SLV0_NACK
            return
        for k in range(ctrl & 0x0F):
            self.regs[0x49 + k] = self.ak.read((self.regs[0x26] + k) & 0xFF)
