"""STM32F103 reset and clock control (RM0008 §7.3) and the flash access control register
(RM0008 §3.3.3), the parts the clock set-up waits on.

Cross-checked with ST's CMSIS stm32f10x.h: RCC_BASE 0x40021000, FLASH_R_BASE 0x40022000,
RCC_CR_HSERDY bit 17, RCC_CR_PLLRDY bit 25, RCC_CFGR_SWS bits 3:2, RCC_CFGR_PLLMULL bits 21:18
(0b0111 = x9), RCC_CFGR_PPRE1 bits 10:8, FLASH_ACR_LATENCY bits 2:0; reset values CR
0x0000XX83, CFGR 0, AHBENR 0x14, CSR 0x0C000000, FLASH_ACR 0x30.

Ready flags come after the start-up times: HSE_STARTUP_US for the crystal (the board option
`hse_present` removes it), PLL_LOCK_US for the PLL (datasheet t_LOCK 200 us max). SW takes
effect only once the chosen source is ready; SWS then follows. Limits the reference manual
states are checked and recorded in `violations`: SYSCLK above the flash wait states' limit
(0 WS up to 24 MHz, 1 up to 48, 2 up to 72), PLL output above 72 MHz, APB1 above 36 MHz.
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_from_us

HSI_HZ = 8_000_000
HSE_HZ = 8_000_000
HSE_STARTUP_US = 2000
PLL_LOCK_US = 200
AHB_DIV = {8: 2, 9: 4, 10: 8, 11: 16, 12: 64, 13: 128, 14: 256, 15: 512}
APB_DIV = {4: 2, 5: 4, 6: 8, 7: 16}


class Rcc(Peripheral):
    name = "RCC"
    base = 0x40021000
    size = 0x400

    def __init__(self, clock, on_hclk_change, hse_present=True):
        self.clock = clock
        self.on_hclk_change = on_hclk_change
        self.hse_present = hse_present
        self.flash_latency = lambda: 0  # set by the board: FLASH_ACR.LATENCY
        self.violations = []
        self.reset()

    def reset(self):
        self.cr = 0x00000083
        self.cfgr = 0
        self.regs = {0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0x14, 0x18: 0, 0x1C: 0, 0x20: 0, 0x24: 0x0C000000}
        self.hse_ready_at = None
        self.pll_ready_at = None
        self.sws = 0

    def _update(self):
        now = self.clock.ticks
        if self.hse_ready_at is not None and now >= self.hse_ready_at:
            self.cr |= 1 << 17
        if self.pll_ready_at is not None and now >= self.pll_ready_at:
            self.cr |= 1 << 25
        sw = self.cfgr & 3
        ready = {0: self.cr & 2, 1: self.cr & (1 << 17), 2: self.cr & (1 << 25)}.get(sw, 0)
        if sw != self.sws and ready:
            self.sws = sw
            self._clocks_changed()

    def pll_hz(self):
        mul = min(((self.cfgr >> 18) & 0xF) + 2, 16)
        if self.cfgr & (1 << 16):
            src = HSE_HZ // 2 if self.cfgr & (1 << 17) else HSE_HZ
        else:
            src = HSI_HZ // 2
        return src * mul

    def sysclk_hz(self):
        return {0: HSI_HZ, 1: HSE_HZ, 2: self.pll_hz()}[self.sws]

    def hclk_hz(self):
        return self.sysclk_hz() // AHB_DIV.get((self.cfgr >> 4) & 0xF, 1)

    def pclk1_hz(self):
        return self.hclk_hz() // APB_DIV.get((self.cfgr >> 8) & 7, 1)

    def pclk2_hz(self):
        return self.hclk_hz() // APB_DIV.get((self.cfgr >> 11) & 7, 1)

    def _clocks_changed(self):
        sysclk = self.sysclk_hz()
        limit = 24_000_000 * (self.flash_latency() + 1)
        if sysclk > limit:
            self.violations.append(f"SYSCLK {sysclk} Hz with {self.flash_latency()} flash wait states")
        if sysclk > 72_000_000:
            self.violations.append(f"SYSCLK {sysclk} Hz above 72 MHz")
        if self.pclk1_hz() > 36_000_000:
            self.violations.append(f"APB1 {self.pclk1_hz()} Hz above 36 MHz")
        self.on_hclk_change(self.hclk_hz())

    def apb1_enabled(self, bit):
        return bool(self.regs[0x1C] >> bit & 1)

    def apb2_enabled(self, bit):
        return bool(self.regs[0x18] >> bit & 1)

    def read(self, offset):
        self._update()
        if offset == 0x00:
            return self.cr
        if offset == 0x04:
            return (self.cfgr & ~0xC) | (self.sws << 2)
        if offset in self.regs:
            return self.regs[offset]
        raise RuntimeError(f"RCC read of offset 0x{offset:02X}")

    def write(self, offset, value):
        self._update()
        if offset == 0x00:
            now = self.clock.ticks
            if value & (1 << 16) and not self.cr & (1 << 16) and self.hse_present:
                self.hse_ready_at = now + ticks_from_us(HSE_STARTUP_US)
            if not value & (1 << 16):
                self.hse_ready_at = None
                value &= ~(1 << 17)
            if value & (1 << 24) and not self.cr & (1 << 24):
                source_ready = self.cr & (1 << 17) if self.cfgr & (1 << 16) else self.cr & 2
                self.pll_ready_at = now + ticks_from_us(PLL_LOCK_US) if source_ready else None
                if self.pll_hz() > 72_000_000:
                    self.violations.append(f"PLL output {self.pll_hz()} Hz above 72 MHz")
            if not value & (1 << 24):
                self.pll_ready_at = None
                value &= ~(1 << 25)
            self.cr = value & ~((1 << 1) | (1 << 17) | (1 << 25))
            if self.cr & 1:
                self.cr |= 1 << 1  # HSIRDY: the HSI runs from reset
            self._update()
        elif offset == 0x04:
            if self.cr & (1 << 24):  # PLLSRC, PLLXTPRE and PLLMUL are locked while the PLL runs
                value = (value & ~0x3F0000) | (self.cfgr & 0x3F0000)
            self.cfgr = value & ~0xC
            self._update()
            self._clocks_changed()
        elif offset in self.regs and offset not in (0x24,):
            self.regs[offset] = value
        else:
            raise RuntimeError(f"RCC write of offset 0x{offset:02X}")


class FlashInterface(Peripheral):
    name = "FLASH"
    base = 0x40022000
    size = 0x400

    def __init__(self):
        self.reset()

    def reset(self):
        self.acr = 0x30

    def latency(self):
        return self.acr & 7

    def read(self, offset):
        if offset == 0x00:
            return self.acr
        if offset in (0x0C, 0x10):  # SR, CR
            return 0x80 if offset == 0x10 else 0  # CR.LOCK after reset
        raise RuntimeError(f"FLASH read of offset 0x{offset:02X}")

    def write(self, offset, value):
        if offset != 0x00:
            raise RuntimeError(f"FLASH write of offset 0x{offset:02X} (programming is not modelled)")
        prftbe = value & 0x10
        self.acr = (value & 0x1F) | (0x20 if prftbe else 0)
