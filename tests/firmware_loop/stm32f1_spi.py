"""STM32F103 SPI in master mode (RM0008 §25.3.3, registers §25.5).

Cross-checked with CMSIS stm32f10x.h: SPI1_BASE 0x40013000; CR1 CPHA bit 0, CPOL 1, MSTR 2,
BR bits 5:3 (f_PCLK / 2^(BR+1)), SPE 6, SSI 8, SSM 9; SR RXNE bit 0, TXE 1, MODF 5, OVR 6,
BSY 7; SR reset 0x0002; CRCPR reset 7.

A byte written to DR moves to the shift register when that is idle (TXE stays set) and is
clocked out in 8 SCK periods of f_PCLK2 / 2^(BR+1), in virtual time; then RXNE is set with
the byte the slave shifted back (OVR if the previous one was not read). The slave is the
device model on the SCK/MISO/MOSI pins: it sees the byte only when the pins are routed
(SCK and MOSI alternate-function outputs), otherwise the master reads 0xFF (MISO floats
high on the breakout's pull-up). Master mode with SSM = 1 needs SSI = 1, otherwise mode fault
(MODF clears MSTR and SPE).
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_per


class Spi(Peripheral):
    def __init__(self, name, base, clock, rcc, enable_bit, pclk_hz, pins_routed):
        self.name, self.base, self.size = name, base, 0x400
        self.clock, self.rcc, self.enable_bit = clock, rcc, enable_bit
        self.pclk_hz = pclk_hz  # callable
        self.pins_routed = pins_routed  # callable: SCK and MOSI configured as AF outputs
        self.slave = None  # .exchange(byte, cpol, cpha, sck_hz) -> byte
        self.transfers = 0
        self.reset()

    def reset(self):
        self.cr1 = 0
        self.cr2 = 0
        self.sr = 0x0002
        self.rx = 0
        self.tx_pending = None
        self.shift_end = None
        self.shift_rx = 0

    def clocked(self):
        return self.rcc.apb2_enabled(self.enable_bit)

    def busy(self):
        self._update()
        return self.shift_end is not None

    def _byte_ticks(self):
        div = 2 ** (((self.cr1 >> 3) & 7) + 1)
        return 8 * div * ticks_per(self.pclk_hz())

    def _start(self, byte):
        cpol, cpha = (self.cr1 >> 1) & 1, self.cr1 & 1
        sck_hz = self.pclk_hz() // 2 ** (((self.cr1 >> 3) & 7) + 1)
        if self.slave is not None and self.pins_routed():
            self.shift_rx = self.slave.exchange(byte, cpol, cpha, sck_hz) & 0xFF
        else:
            self.shift_rx = 0xFF
        self.shift_end = self.clock.ticks + self._byte_ticks()
        self.transfers += 1

    def _update(self):
        while self.shift_end is not None and self.clock.ticks >= self.shift_end:
            end = self.shift_end
            self.shift_end = None
            if self.sr & 1:
                self.sr |= 1 << 6  # OVR: the previous byte was not read
            else:
                self.rx = self.shift_rx
                self.sr |= 1
            if self.tx_pending is not None:
                byte, self.tx_pending = self.tx_pending, None
                self.sr |= 2
                self._start(byte)
                self.shift_end = end + self._byte_ticks()

    def enabled_master(self):
        return self.cr1 & (1 << 6) and self.cr1 & (1 << 2)

    def read(self, offset):
        self._update()
        if offset == 0x00:
            return self.cr1
        if offset == 0x04:
            return self.cr2
        if offset == 0x08:
            bsy = 0x80 if self.shift_end is not None or self.tx_pending is not None else 0
            return (self.sr & 0x7F) | bsy
        if offset == 0x0C:
            self.sr &= ~1
            return self.rx
        if offset == 0x10:
            return 7
        if offset in (0x14, 0x18, 0x1C):
            return 0
        raise RuntimeError(f"{self.name} read of offset 0x{offset:02X}")

    def write(self, offset, value):
        self._update()
        if offset == 0x00:
            if value & (1 << 2) and value & (1 << 9) and not value & (1 << 8):
                self.sr |= 1 << 5  # MODF: SSM with SSI low in master mode
                value &= ~((1 << 2) | (1 << 6))
            self.cr1 = value & 0xFFFF
        elif offset == 0x04:
            self.cr2 = value & 0xFF
        elif offset == 0x0C:
            if not self.enabled_master():
                return
            if self.shift_end is None:
                self._start(value & 0xFF)
            else:
                self.tx_pending = value & 0xFF
                self.sr &= ~2
        elif offset in (0x08, 0x10, 0x1C, 0x20):
            pass
        else:
            raise RuntimeError(f"{self.name} write of offset 0x{offset:02X}")
