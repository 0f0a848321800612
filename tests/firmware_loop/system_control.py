"""The Cortex-M3 System Control Space at 0xE000E000: SysTick, NVIC and the SCB registers the
images touch. Written from the ARMv7-M Architecture Reference Manual (B3.2 SCS, B3.3 SysTick,
B3.4 NVIC) and PM0056 (STM32F10xxx Cortex-M3 programming manual, §4); cross-checked with
CMSIS core_cm3.h (SysTick_BASE 0xE000E010, NVIC_BASE 0xE000E100, SCB_BASE 0xE000ED00,
ICSR.PENDSTSET bit 26, SysTick CTRL.COUNTFLAG bit 16) and the STM32F1 device header
(__NVIC_PRIO_BITS 4: only the top four bits of a priority byte exist).

The model keeps the exception state (pending, active, priorities); the CPU (cortex_m.py)
asks it which exception to take and tells it when one is entered and returned from.
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_per

SYSTICK_EXC = 15
IRQ_BASE = 16
PRIO_MASK = 0xF0  # __NVIC_PRIO_BITS = 4

CPUID_CORTEX_M3_R1P1 = 0x411FC231  # PM0056 §4.4.1: the STM32F10x core
CPUID_CORTEX_M4_R0P1 = 0x410FC241  # PM0214 §4.3.1: the STM32F4 core
CCR_RESET = 0x00000200  # STKALIGN
FPCCR_RESET = 0xC0000000  # ASPEN, LSPEN (PM0214 §4.6.2)


class SystemControl(Peripheral):
    name = "SCS"
    base = 0xE000E000
    size = 0x1000

    def __init__(self, clock, irq_count, cpuid=CPUID_CORTEX_M3_R1P1, fpu=False):
        self.clock = clock
        self.cpuid, self.fpu = cpuid, fpu
        self.irq_count = irq_count
        self.hclk_hz = 8_000_000  # the core clock; the RCC model reports changes (set_hclk)
        self.reset()

    def set_hclk(self, hz):
        self.hclk_hz = hz

    def reset(self):
        self.st_ctrl = 0
        self.st_load = 0
        self.st_frozen_val = 0
        self.st_start = 0  # tick at which the counter (re)started from VAL = 0
        self.st_wraps_seen = 0
        self.enabled = set()  # IRQ numbers
        self.pending = set()  # exception numbers
        self.active = []  # stack of exception numbers being handled
        self.priority = {}  # exception number -> priority byte
        self.vtor = 0
        self.ccr = CCR_RESET
        self.cpacr = 0
        self.fpccr = FPCCR_RESET if self.fpu else 0
        self.reset_requested = False

    # --- SysTick (ARMv7-M B3.3): counts down from LOAD, wraps to LOAD, pends on 1 -> 0 ---
    def _st_period(self):
        hz = self.hclk_hz if self.st_ctrl & 4 else self.hclk_hz // 8
        return ticks_per(hz)

    def _st_counts(self):
        return (self.clock.ticks - self.st_start) // self._st_period()

    def systick_update(self):
        """Brings COUNTFLAG and the SysTick pending state up to the current time."""
        if not self.st_ctrl & 1 or self.st_load == 0:
            return
        wraps = self._st_counts() // (self.st_load + 1)
        if wraps > self.st_wraps_seen:
            self.st_wraps_seen = wraps
            self.st_ctrl |= 1 << 16
            if self.st_ctrl & 2:
                self.pending.add(SYSTICK_EXC)

    def next_event_tick(self):
        """Tick of the next SysTick wrap, or None."""
        if not self.st_ctrl & 1 or self.st_load == 0 or not self.st_ctrl & 2:
            return None
        return self.st_start + (self.st_wraps_seen + 1) * (self.st_load + 1) * self._st_period()

    def _st_val(self):
        if not self.st_ctrl & 1:
            return self.st_frozen_val
        k = self._st_counts()
        return 0 if k == 0 else self.st_load - ((k - 1) % (self.st_load + 1))

    # --- exception state ---
    def exc_priority(self, exc):
        if exc < 4:
            return {1: -3, 2: -2, 3: -1}.get(exc, 0)
        return self.priority.get(exc, 0) & PRIO_MASK

    def execution_priority(self, primask):
        prio = 256
        for exc in self.active:
            prio = min(prio, self.exc_priority(exc))
        if primask:
            prio = min(prio, 0)
        return prio

    def take(self, primask):
        """The pending exception that preempts now, or None."""
        self.systick_update()
        candidates = [e for e in self.pending if e < IRQ_BASE or (e - IRQ_BASE) in self.enabled]
        if not candidates:
            return None
        best = min(candidates, key=lambda e: (self.exc_priority(e), e))
        return best if self.exc_priority(best) < self.execution_priority(primask) else None

    def waiting(self):
        """An enabled exception is pending but may not preempt yet (priority, PRIMASK)."""
        return any(e < IRQ_BASE or (e - IRQ_BASE) in self.enabled for e in self.pending)

    def set_irq_pending(self, irq, level):
        if level:
            self.pending.add(IRQ_BASE + irq)

    def entered(self, exc):
        self.pending.discard(exc)
        self.active.append(exc)

    def returned(self, exc):
        if not self.active or self.active[-1] != exc:
            raise RuntimeError(f"exception return from {exc}, active {self.active}")
        self.active.pop()

    # --- registers ---
    def read(self, offset):
        self.systick_update()
        if offset == 0x010:
            value = self.st_ctrl
            self.st_ctrl &= ~(1 << 16)  # COUNTFLAG clears on read
            return value
        if offset == 0x014:
            return self.st_load
        if offset == 0x018:
            return self._st_val()
        if offset == 0x01C:
            return 0x40000000 | 9000  # CALIB: NOREF, TENMS for 9 MHz (PM0056 §4.5.4)
        if 0x100 <= offset < 0x120 or 0x180 <= offset < 0x1A0:
            return self._irq_bits(self.enabled, (offset & 0x1F) // 4)
        if 0x200 <= offset < 0x220 or 0x280 <= offset < 0x2A0:
            return self._irq_bits({e - IRQ_BASE for e in self.pending if e >= IRQ_BASE}, (offset & 0x1F) // 4)
        if 0x300 <= offset < 0x320:
            return self._irq_bits({e - IRQ_BASE for e in self.active if e >= IRQ_BASE}, (offset & 0x1F) // 4)
        if 0x400 <= offset < 0x400 + self.irq_count:
            return self._prio_word(IRQ_BASE + offset - 0x400)
        if offset == 0xD00:
            return self.cpuid
        if offset == 0xD88:
            return self.cpacr
        if offset == 0xF34 and self.fpu:
            return self.fpccr
        if offset == 0xD04:
            value = self.active[-1] if self.active else 0
            if SYSTICK_EXC in self.pending:
                value |= 1 << 26
            return value
        if offset == 0xD08:
            return self.vtor
        if offset == 0xD0C:
            return 0xFA050000
        if offset == 0xD14:
            return self.ccr
        if offset in (0xD18, 0xD1C, 0xD20):
            return self._prio_word(4 + (offset - 0xD18))
        if offset in (0xD10, 0xD24, 0xD28, 0xD2C):
            return 0
        raise RuntimeError(f"SCS read of unmodelled offset 0x{offset:03X}")

    def _irq_bits(self, irqs, word):
        return sum(1 << (i - 32 * word) for i in irqs if 32 * word <= i < 32 * word + 32)

    def _prio_word(self, first_exc):
        return sum(self.priority.get(first_exc + i, 0) << (8 * i) for i in range(4))

    def write_bytes(self, offset, size, value):
        if 0x400 <= offset < 0x400 + self.irq_count or 0xD18 <= offset < 0xD24:
            first = IRQ_BASE + offset - 0x400 if offset < 0xD00 else 4 + offset - 0xD18
            for i in range(size):
                self.priority[first + i] = ((value >> (8 * i)) & 0xFF) & PRIO_MASK
            return
        raise RuntimeError(f"SCS byte write of unmodelled offset 0x{offset:03X}")

    def write(self, offset, value):
        self.systick_update()
        if offset == 0x010:
            was_on = self.st_ctrl & 1
            if was_on and not value & 1:
                self.st_frozen_val = self._st_val()
            self.st_ctrl = (self.st_ctrl & (1 << 16)) | (value & 7)
            if value & 1 and not was_on:
                self.st_start, self.st_wraps_seen = self.clock.ticks, 0
        elif offset == 0x014:
            self.st_load = value & 0xFFFFFF
        elif offset == 0x018:  # any write clears VAL and COUNTFLAG
            self.st_ctrl &= ~(1 << 16)
            self.st_frozen_val = 0
            if self.st_ctrl & 1:
                self.st_start, self.st_wraps_seen = self.clock.ticks, 0
        elif 0x100 <= offset < 0x120:
            self.enabled |= {32 * ((offset - 0x100) // 4) + b for b in range(32) if value >> b & 1}
        elif 0x180 <= offset < 0x1A0:
            self.enabled -= {32 * ((offset - 0x180) // 4) + b for b in range(32) if value >> b & 1}
        elif 0x200 <= offset < 0x220:
            self.pending |= {IRQ_BASE + 32 * ((offset - 0x200) // 4) + b for b in range(32) if value >> b & 1}
        elif 0x280 <= offset < 0x2A0:
            self.pending -= {IRQ_BASE + 32 * ((offset - 0x280) // 4) + b for b in range(32) if value >> b & 1}
        elif 0x400 <= offset < 0x400 + self.irq_count or 0xD18 <= offset < 0xD24:
            self.write_bytes(offset, 4, value)
        elif offset == 0xD04:
            if value & (1 << 26):
                self.pending.add(SYSTICK_EXC)
            if value & (1 << 25):
                self.pending.discard(SYSTICK_EXC)
        elif offset == 0xD08:
            self.vtor = value & 0x3FFFFF80
        elif offset == 0xD0C:
            if value >> 16 == 0x05FA and value & 4:  # VECTKEY + SYSRESETREQ
                self.reset_requested = True
        elif offset == 0xD14:
            self.ccr = value & 0x31A
        elif offset == 0xD88:
            # CPACR: CP10/CP11 exist only with an FPU (the M3 ignores the write, reads 0).
            self.cpacr = value & 0x00F00000 if self.fpu else 0
        elif offset == 0xF34 and self.fpu:
            self.fpccr = value & 0xC0000000
        elif offset in (0xD10, 0xD24):
            pass  # SCR, SHCSR
        else:
            raise RuntimeError(f"SCS write of unmodelled offset 0x{offset:03X}")
