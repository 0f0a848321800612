"""STM32F407 reset and clock control (RM0090 §7.3), power controller (§5.4) and flash access
control register (§3.9.1): the parts the sink's clock set-up writes and waits on.

Cross-checked with ST's CMSIS stm32f407xx.h: RCC_BASE 0x40023800, PWR_BASE 0x40007000,
FLASH_R_BASE 0x40023C00; RCC_CR_HSEON bit 16, HSERDY 17, PLLON 24, PLLRDY 25; RCC_PLLCFGR
PLLM bits 5:0, PLLN 14:6, PLLP 17:16, PLLSRC 22, PLLQ 27:24 (reset 0x24003010); RCC_CFGR SW
bits 1:0, SWS 3:2, HPRE 7:4, PPRE1 12:10, PPRE2 15:13; AHB1ENR at 0x30 (reset 0x00100000,
CCMDATARAMEN), APB1ENR 0x40, APB2ENR 0x44; PWR_CR VOS bit 14, PWR_CSR VOSRDY bit 14;
FLASH_ACR LATENCY bits 2:0, PRFTEN 8, ICEN 9, DCEN 10.

Ready flags come after start-up times (HSE_STARTUP_US, PLL_LOCK_US; the board option
`hse_present` removes the crystal). SW takes effect once its source is ready; SWS follows.
The limits RM0090 states are checked and recorded in `violations`: SYSCLK above what the
flash wait states allow at 2.7-3.6 V (30 MHz per wait state, table 10), the PLL's VCO input
outside 1-2 MHz and output outside 100-432 MHz, SYSCLK above 168 MHz, APB1 above 42 MHz and
APB2 above 84 MHz, 168 MHz without regulator scale 1 (VOS).
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_from_us

HSI_HZ = 16_000_000
HSE_HZ = 8_000_000
HSE_STARTUP_US = 2000
PLL_LOCK_US = 200
AHB_DIV = {8: 2, 9: 4, 10: 8, 11: 16, 12: 64, 13: 128, 14: 256, 15: 512}
APB_DIV = {4: 2, 5: 4, 6: 8, 7: 16}
HSEON, HSERDY, PLLON, PLLRDY = 1 << 16, 1 << 17, 1 << 24, 1 << 25


class Rcc(Peripheral):
    name = "RCC"
    base = 0x40023800
    size = 0x400

    def __init__(self, clock, on_hclk_change, hse_present=True):
        self.clock = clock
        self.on_hclk_change = on_hclk_change
        self.hse_present = hse_present
        self.flash_latency = lambda: 0  # set by the board: FLASH_ACR.LATENCY
        self.vos_scale1 = lambda: True  # set by the board: PWR_CR.VOS
        self.violations = []
        self.reset()

    def reset(self):
        self.cr = 0x00000083
        self.pllcfgr = 0x24003010
        self.cfgr = 0
        # CIR, AHB1-3RSTR, APB1/2RSTR, AHB1-3ENR, APB1/2ENR, low-power enables, BDCR, CSR ...
        self.regs = {off: 0 for off in range(0x0C, 0x8C, 4)}
        self.regs[0x30] = 0x00100000
        self.regs[0x74] = 0x0E000000  # CSR: reset flags after power-on
        self.hse_ready_at = None
        self.pll_ready_at = None
        self.sws = 0
        self._hclk = None

    def _update(self):
        now = self.clock.ticks
        if self.hse_ready_at is not None and now >= self.hse_ready_at:
            self.cr |= HSERDY
        if self.pll_ready_at is not None and now >= self.pll_ready_at:
            self.cr |= PLLRDY
        sw = self.cfgr & 3
        ready = {0: self.cr & 2, 1: self.cr & HSERDY, 2: self.cr & PLLRDY}.get(sw, 0)
        if sw != self.sws and ready:
            self.sws = sw
            self._clocks_changed()

    def _pll_parts(self):
        m = self.pllcfgr & 0x3F
        n = (self.pllcfgr >> 6) & 0x1FF
        p = 2 * (((self.pllcfgr >> 16) & 3) + 1)
        src = HSE_HZ if self.pllcfgr & (1 << 22) else HSI_HZ
        return src, m, n, p

    def pll_hz(self):
        src, m, n, p = self._pll_parts()
        return src // max(m, 1) * n // p

    def sysclk_hz(self):
        return {0: HSI_HZ, 1: HSE_HZ, 2: self.pll_hz()}[self.sws]

    def hclk_hz(self):
        if self._hclk is None:  # read on every timer access: kept until the clocks change
            self._hclk = self.sysclk_hz() // AHB_DIV.get((self.cfgr >> 4) & 0xF, 1)
        return self._hclk

    def pclk1_hz(self):
        return self.hclk_hz() // APB_DIV.get((self.cfgr >> 10) & 7, 1)

    def pclk2_hz(self):
        return self.hclk_hz() // APB_DIV.get((self.cfgr >> 13) & 7, 1)

    def tim_apb1_hz(self):
        """Timers on APB1 run at twice PCLK1 when the APB1 prescaler divides (RM0090 §7.2)."""
        return self.pclk1_hz() * (2 if (self.cfgr >> 10) & 4 else 1)

    def _clocks_changed(self):
        self._hclk = None
        sysclk = self.sysclk_hz()
        if sysclk > 30_000_000 * (self.flash_latency() + 1):
            self.violations.append(f"SYSCLK {sysclk} Hz with {self.flash_latency()} flash wait states")
        if sysclk > 168_000_000:
            self.violations.append(f"SYSCLK {sysclk} Hz above 168 MHz")
        if sysclk > 144_000_000 and not self.vos_scale1():
            self.violations.append(f"SYSCLK {sysclk} Hz without regulator scale 1")
        if self.pclk1_hz() > 42_000_000:
            self.violations.append(f"APB1 {self.pclk1_hz()} Hz above 42 MHz")
        if self.pclk2_hz() > 84_000_000:
            self.violations.append(f"APB2 {self.pclk2_hz()} Hz above 84 MHz")
        self.on_hclk_change(self.hclk_hz())

    def _check_pll(self):
        src, m, n, p = self._pll_parts()
        vco_in = src / max(m, 1)
        if not 1e6 <= vco_in <= 2e6:
            self.violations.append(f"PLL VCO input {vco_in:.0f} Hz outside 1-2 MHz")
        if not 100e6 <= vco_in * n <= 432e6:
            self.violations.append(f"PLL VCO output {vco_in * n:.0f} Hz outside 100-432 MHz")

    def ahb1_enabled(self, bit):
        return bool(self.regs[0x30] >> bit & 1)

    def apb1_enabled(self, bit):
        return bool(self.regs[0x40] >> bit & 1)

    def apb2_enabled(self, bit):
        return bool(self.regs[0x44] >> bit & 1)

    def read(self, offset):
        self._update()
        if offset == 0x00:
            return self.cr
        if offset == 0x04:
            return self.pllcfgr
        if offset == 0x08:
            return (self.cfgr & ~0xC) | (self.sws << 2)
        if offset in self.regs:
            return self.regs[offset]
        raise RuntimeError(f"RCC read of offset 0x{offset:02X}")

    def write(self, offset, value):
        self._update()
        if offset == 0x00:
            now = self.clock.ticks
            if value & HSEON and not self.cr & HSEON and self.hse_present:
                self.hse_ready_at = now + ticks_from_us(HSE_STARTUP_US)
            if not value & HSEON:
                self.hse_ready_at = None
                value &= ~HSERDY
            if value & PLLON and not self.cr & PLLON:
                source_ready = self.cr & HSERDY if self.pllcfgr & (1 << 22) else self.cr & 2
                self.pll_ready_at = now + ticks_from_us(PLL_LOCK_US) if source_ready else None
                self._check_pll()
            if not value & PLLON:
                self.pll_ready_at = None
                value &= ~PLLRDY
            self.cr = (value & ~(2 | HSERDY | PLLRDY)) | (self.cr & (HSERDY | PLLRDY) & (value << 1))
            if self.cr & 1:
                self.cr |= 2  # HSIRDY: the HSI runs from reset
            self._update()
        elif offset == 0x04:
            if self.cr & PLLON:
                self.violations.append("PLLCFGR written while the PLL is on (ignored)")
            else:
                self.pllcfgr = value
        elif offset == 0x08:
            self.cfgr = value & ~0xC
            self._update()
            self._clocks_changed()
        elif offset in self.regs:
            self.regs[offset] = value
        else:
            raise RuntimeError(f"RCC write of offset 0x{offset:02X}")


class Pwr(Peripheral):
    """PWR_CR / PWR_CSR. VOS resets to 1 (scale 1) on the F407 (RM0090 §5.4.1); VOSRDY is
    set once the regulator runs at the selected scale (here: at once)."""

    name = "PWR"
    base = 0x40007000
    size = 0x400

    def __init__(self, rcc):
        self.rcc = rcc
        self.reset()

    def reset(self):
        self.cr = 0x00004000

    def clocked(self):
        return self.rcc.apb1_enabled(28)

    def vos_scale1(self):
        return bool(self.cr & (1 << 14))

    def read(self, offset):
        if offset == 0x00:
            return self.cr
        if offset == 0x04:
            return 1 << 14  # VOSRDY
        raise RuntimeError(f"PWR read of offset 0x{offset:02X}")

    def write(self, offset, value):
        if offset == 0x00:
            self.cr = value
        elif offset != 0x04:
            raise RuntimeError(f"PWR write of offset 0x{offset:02X}")


class FlashInterface(Peripheral):
    name = "FLASH"
    base = 0x40023C00
    size = 0x400

    def __init__(self):
        self.reset()

    def reset(self):
        self.acr = 0

    def latency(self):
        return self.acr & 7

    def read(self, offset):
        if offset == 0x00:
            return self.acr
        if offset in (0x0C, 0x10):  # SR, CR (LOCK after reset)
            return 0x80000000 if offset == 0x10 else 0
        raise RuntimeError(f"FLASH read of offset 0x{offset:02X}")

    def write(self, offset, value):
        if offset != 0x00:
            raise RuntimeError(f"FLASH write of offset 0x{offset:02X} (programming is not modelled)")
        self.acr = value & 0x0707  # LATENCY, PRFTEN, ICEN, DCEN (the reset bits read 0)
