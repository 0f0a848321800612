"""General-purpose timer TIM2 of the STM32F4 as a free-running up-counter (RM0090 §18.4).

Cross-checked with CMSIS stm32f407xx.h: TIM2_BASE 0x40000000 (APB1ENR bit 0); CR1 0x00 (CEN
bit 0), DIER 0x0C, SR 0x10 (UIF bit 0), EGR 0x14 (UG bit 0), CNT 0x24, PSC 0x28, ARR 0x2C
(reset 0xFFFFFFFF on the 32-bit TIM2). PSC is preloaded: a new prescaler takes effect at the
next update event (UG or overflow), as on silicon, so an image that forgets UG counts at the
old rate until the first overflow. Counting: CK_CNT = timer clock / (PSC + 1), from CNT up
to ARR, then 0 (UIF set). No capture/compare, no interrupt (the sink polls CNT).
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_per


class Timer(Peripheral):
    size = 0x400

    def __init__(self, name, base, rcc, enable_bit, clock, timer_hz):
        self.name, self.base, self.rcc, self.enable_bit = name, base, rcc, enable_bit
        self.clock, self.timer_hz = clock, timer_hz
        self._hz = self._tick_len = None
        self.reset()

    def reset(self):
        self.cr1 = self.dier = self.sr = 0
        self.psc_preload = self.psc = 0
        self.arr = 0xFFFFFFFF
        self.cnt0, self.tick0 = 0, 0  # CNT at tick0 while counting
        self.regs = {0x04: 0, 0x08: 0, 0x18: 0, 0x1C: 0, 0x20: 0}

    def clocked(self):
        return self.rcc.apb1_enabled(self.enable_bit)

    def _period(self):
        hz = self.timer_hz()
        if hz != self._hz:
            self._hz, self._tick_len = hz, ticks_per(hz)
        return self._tick_len * (self.psc + 1)

    def _cnt(self):
        if not self.cr1 & 1:
            return self.cnt0
        period = self._period()
        counts = (self.clock.ticks - self.tick0) // period
        if self.cnt0 + counts <= self.arr:
            return self.cnt0 + counts
        # Overflow: update event (UIF) at its own instant; the preloaded PSC applies from there.
        self.tick0 += (self.arr + 1 - self.cnt0) * period
        self.cnt0 = 0
        self.sr |= 1
        self.psc = self.psc_preload
        return self._cnt()

    def _rebase(self, cnt):
        self.cnt0, self.tick0 = cnt, self.clock.ticks
        self.psc = self.psc_preload

    def read(self, offset):
        cnt = self._cnt()
        if offset == 0x24:
            return cnt
        value = {0x00: self.cr1, 0x0C: self.dier, 0x10: self.sr, 0x14: 0, 0x28: self.psc_preload,
                 0x2C: self.arr}.get(offset)
        if value is None:
            value = self.regs.get(offset)
        if value is None:
            raise RuntimeError(f"{self.name} read of offset 0x{offset:02X}")
        return value

    def write(self, offset, value):
        cnt = self._cnt()
        if offset == 0x00:
            self.cr1 = value & 0x3FF
            self.cnt0, self.tick0 = cnt, self.clock.ticks
        elif offset == 0x0C:
            self.dier = value
        elif offset == 0x10:
            self.sr &= value  # rc_w0
        elif offset == 0x14:
            if value & 1:  # UG: counter to 0, prescaler loaded
                self._rebase(0)
        elif offset == 0x24:
            self.cnt0, self.tick0 = value, self.clock.ticks
        elif offset == 0x28:
            self.psc_preload = value & 0xFFFF
        elif offset == 0x2C:
            self.arr = value
        elif offset in self.regs:
            self.regs[offset] = value
        else:
            raise RuntimeError(f"{self.name} write of offset 0x{offset:02X}")
