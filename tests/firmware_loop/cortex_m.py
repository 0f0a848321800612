"""A Cortex-M3 or Cortex-M4F running an unmodified ELF image in unicorn, on virtual time.

Unicorn executes the instructions; everything around them is here, as the ARMv7-M
Architecture Reference Manual specifies it, because unicorn 2.0 does not do it:
- reset (B1.5.5): SP_main from word 0 of the vector table, PC from word 1 (its bit 0 must be
  set: Thumb), the table read through the boot alias of flash at 0x00000000;
- exception entry (B1.5.6 PushStack/ExceptionTaken): eight words R0-R3, R12, LR, return
  address, xPSR pushed on the main stack, aligned to 8 bytes when CCR.STKALIGN is set (xPSR
  bit 9 records the padding), LR = EXC_RETURN (0xFFFFFFF9 from Thread mode, 0xFFFFFFF1 when
  nesting), PC from the vector table at VTOR;
- exception return (B1.5.8): unicorn raises its internal EXCEPTION_EXIT (interrupt 8) when the
  PC is loaded with 0xFFFFFFFx; the frame is popped and the flags restored here.
- with the FPU (Cortex-M4F, B1.5.7): when CONTROL.FPCA is set at entry the frame is the
  extended one (26 words: S0-S15 and FPSCR after the eight, one reserved word) and EXC_RETURN
  has bit 4 clear (0xFFFFFFE9 / 0xFFFFFFE1); the return pops it and sets FPCA again. The
  registers are stored at entry (the lazy preservation of FPCCR.LSPEN reserves the same
  space and saves them only if the handler uses the FPU: the program cannot tell).
Unicorn runs slices of at most SLICE instructions (it counts them exactly); time advances by
that count at the current SYSCLK (virtual_clock.py) and a slice ends at the next SysTick wrap,
so an exception is taken within SLICE instructions of its event (the real core takes 12
cycles). Inside a slice the models see the time of the slice's start: a polling loop sees a
register change up to SLICE instructions late. No Python runs per instruction or per block,
only per slice and per peripheral access. Only the main stack is
supported: an image that selects the process stack stops with a fault.
"""

import ctypes

from unicorn import UC_ARCH_ARM, UC_HOOK_INTR, UC_MODE_MCLASS, UC_MODE_THUMB, UC_PROT_ALL, Uc, UcError
from unicorn.arm_const import (UC_ARM_REG_CONTROL, UC_ARM_REG_LR, UC_ARM_REG_PC, UC_ARM_REG_PRIMASK, UC_ARM_REG_R0,
                               UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R12, UC_ARM_REG_SP,
                               UC_ARM_REG_XPSR, UC_ARM_REG_XPSR_NZCVQ, UC_CPU_ARM_CORTEX_M3, UC_ARM_REG_S0,
                               UC_ARM_REG_FPSCR)

import elf_image
from mmio_bus import MmioBus
from virtual_clock import Clock, ticks_per

EXCP_EXCEPTION_EXIT = 8  # QEMU's internal exception number for a PC of 0xFFFFFFFx
FRAME_REGS = (UC_ARM_REG_R0, UC_ARM_REG_R1, UC_ARM_REG_R2, UC_ARM_REG_R3, UC_ARM_REG_R12, UC_ARM_REG_LR)
SLICE = 500  # instructions between looks at the exception state (7 us at 72 MHz)
WAIT_SLICE = 16  # while an exception waits to be taken


class CortexM:
    def __init__(self, flash_base, flash_size, ram_base, ram_size, cpu_model=UC_CPU_ARM_CORTEX_M3, fpu=False):
        self.uc = Uc(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS)
        self.uc.ctl_set_cpu_model(cpu_model)
        self.fpu = fpu
        self.flash_base, self.flash_size = flash_base, flash_size
        self._flash = ctypes.create_string_buffer(flash_size)
        self.uc.mem_map_ptr(flash_base, flash_size, UC_PROT_ALL, self._flash)
        self.uc.mem_map_ptr(0, flash_size, UC_PROT_ALL, self._flash)  # BOOT0 = 0: flash at 0
        self.uc.mem_map(ram_base, ram_size, UC_PROT_ALL)
        # SRAM powers up with unknown content: a fixed pattern, so a read before write shows.
        self.uc.mem_write(ram_base, bytes((i * 151 + 89) & 0xFF for i in range(ram_size)))
        self.clock = Clock()
        self.bus = MmioBus(self.uc)
        self.scs = None  # SystemControl, attached by the board
        self.ticks_per_cycle = ticks_per(8_000_000)  # HSI after reset
        self.fault = None
        self.resets = 0
        self.exceptions_taken = {}  # exception number -> entries
        self.on_reset = []  # peripheral reset callbacks (system reset request)
        self.slice = SLICE  # a board whose every event source cuts slices may take longer ones
        self.timed = []  # models with update() and next_event_tick(): brought to time per slice
        self.uc.hook_add(UC_HOOK_INTR, self._on_intr)

    def program(self, elf_path):
        """Writes the ELF's loadable bytes into flash, as a programmer would (erased = 0xFF)."""
        ctypes.memset(self._flash, 0xFF, self.flash_size)
        for address, data in elf_image.load_segments(elf_path):
            if not (self.flash_base <= address and address + len(data) <= self.flash_base + self.flash_size):
                raise elf_image.ElfError(f"segment at 0x{address:08X} is not in flash")
            self.uc.mem_write(address, data)

    def set_sysclk(self, hz):
        self.ticks_per_cycle = ticks_per(hz)

    def reset(self):
        vector = self.uc.mem_read(self.scs.vtor, 8)
        sp = int.from_bytes(vector[0:4], "little")
        pc = int.from_bytes(vector[4:8], "little")
        if not pc & 1:
            self._set_fault(f"reset vector 0x{pc:08X} without the Thumb bit (INVSTATE)")
        self.uc.reg_write(UC_ARM_REG_SP, sp & ~3)
        self.uc.reg_write(UC_ARM_REG_LR, 0xFFFFFFFF)
        self.uc.reg_write(UC_ARM_REG_PRIMASK, 0)
        self.uc.reg_write(UC_ARM_REG_PC, pc | 1)

    def pin_reset(self):
        """NRST pulled low and released: the same system reset as SYSRESETREQ."""
        self._system_reset()

    def _system_reset(self):
        self.resets += 1
        self.scs.reset()
        for callback in self.on_reset:
            callback()
        self.set_sysclk(8_000_000)  # the RCC is back on the HSI
        self.scs.set_hclk(8_000_000)
        self.reset()

    def _set_fault(self, text):
        if self.fault is None:
            self.fault = f"{text} at {self.clock.cycles} cycles"

    # --- execution ---
    def run_until(self, tick):
        """Runs until virtual time `tick`, in slices of at most SLICE instructions that end
        at the next SysTick wrap; exceptions are taken between slices."""
        uc = self.uc
        while self.clock.ticks < tick and self.fault is None:
            if self.scs.reset_requested:
                self._system_reset()
            for model in self.timed:
                model.update()
            pc = uc.reg_read(UC_ARM_REG_PC)
            exc = self.scs.take(uc.reg_read(UC_ARM_REG_PRIMASK) & 1)
            if exc is not None and not self._in_it_block():
                self._enter(exc, pc)
                continue
            until = tick
            for upcoming in [self.scs.next_event_tick()] + [m.next_event_tick() for m in self.timed]:
                if upcoming is not None and upcoming > self.clock.ticks:
                    until = min(until, upcoming)
            n = -(-(until - self.clock.ticks) // self.ticks_per_cycle)
            # A pending exception held back (an active handler of higher priority, PRIMASK, an
            # IT block) is taken within WAIT_SLICE instructions of becoming possible, as the
            # core takes it (tail-chaining) instead of at the end of a full slice.
            n = max(1, min(WAIT_SLICE if self.scs.waiting() else self.slice, n))
            try:
                uc.emu_start(pc | 1, 0xFFFFFFFF, count=n)
            except UcError as e:
                self._set_fault(f"{e} (PC 0x{uc.reg_read(UC_ARM_REG_PC):08X})")
            if self.bus.error:
                self._set_fault(self.bus.error)
            self.clock.cycles += n
            self.clock.ticks += n * self.ticks_per_cycle

    def _in_it_block(self):
        xpsr = self.uc.reg_read(UC_ARM_REG_XPSR)
        return bool((xpsr >> 25) & 3 or (xpsr >> 10) & 0x3F)

    def _enter(self, exc, return_address):
        uc = self.uc
        if uc.reg_read(UC_ARM_REG_CONTROL) & 2:
            self._set_fault("exception entry with the process stack selected (not modelled)")
            uc.emu_stop()
            return
        sp = uc.reg_read(UC_ARM_REG_SP)
        control = uc.reg_read(UC_ARM_REG_CONTROL)
        extended = self.fpu and bool(control & 4)  # FPCA: a floating-point context is live
        size = 104 if extended else 32
        align = 1 if (self.scs.ccr & 0x200) and ((sp - size) & 4) else 0
        frame = (sp - size) & ~7 if align else sp - size
        ipsr = self.scs.active[-1] if self.scs.active else 0
        xpsr = (uc.reg_read(UC_ARM_REG_XPSR) & ~0x3FF) | ipsr | (align << 9)
        words = [uc.reg_read(r) for r in FRAME_REGS] + [return_address, xpsr]
        if extended:
            words += [self._sreg(i) for i in range(16)] + [uc.reg_read(UC_ARM_REG_FPSCR), 0]
            uc.reg_write(UC_ARM_REG_CONTROL, control & ~4)
        uc.mem_write(frame, b"".join(w.to_bytes(4, "little") for w in words))
        uc.reg_write(UC_ARM_REG_SP, frame)
        exc_return = 0xFFFFFFF1 if self.scs.active else 0xFFFFFFF9
        uc.reg_write(UC_ARM_REG_LR, exc_return & ~0x10 if extended else exc_return)
        self.scs.entered(exc)
        self.exceptions_taken[exc] = self.exceptions_taken.get(exc, 0) + 1
        handler = int.from_bytes(uc.mem_read(self.scs.vtor + 4 * exc, 4), "little")
        if not handler & 1:
            self._set_fault(f"vector {exc} = 0x{handler:08X} without the Thumb bit")
            uc.emu_stop()
            return
        uc.reg_write(UC_ARM_REG_PC, handler | 1)
        self.clock.cycles += 12  # entry latency of the Cortex-M3 (PM0056 §2.3.7)
        self.clock.ticks += 12 * self.ticks_per_cycle

    def _sreg(self, i):
        return self.uc.reg_read(UC_ARM_REG_S0 + i) & 0xFFFFFFFF

    def _on_intr(self, uc, intno, _):
        if intno != EXCP_EXCEPTION_EXIT:
            self._set_fault(f"CPU exception {intno} at PC 0x{uc.reg_read(UC_ARM_REG_PC):08X} (a HardFault on silicon)")
            uc.emu_stop()
            return
        exc_return = uc.reg_read(UC_ARM_REG_PC) | 1
        if not self.scs.active:
            self._set_fault(f"EXC_RETURN 0x{exc_return:08X} in Thread mode")
            uc.emu_stop()
            return
        extended = self.fpu and not exc_return & 0x10
        basic = exc_return | 0x10 if self.fpu else exc_return
        to_thread = basic == 0xFFFFFFF9
        if basic not in (0xFFFFFFF1, 0xFFFFFFF9) or to_thread != (len(self.scs.active) == 1):
            self._set_fault(f"EXC_RETURN 0x{exc_return:08X} with active {self.scs.active} (INVPC)")
            uc.emu_stop()
            return
        sp = uc.reg_read(UC_ARM_REG_SP)
        size = 104 if extended else 32
        raw = uc.mem_read(sp, size)
        words = [int.from_bytes(raw[4 * i:4 * i + 4], "little") for i in range(size // 4)]
        for reg, value in zip(FRAME_REGS, words):
            uc.reg_write(reg, value)
        if extended:
            for i in range(16):
                uc.reg_write(UC_ARM_REG_S0 + i, words[8 + i])
            uc.reg_write(UC_ARM_REG_FPSCR, words[24])
            uc.reg_write(UC_ARM_REG_CONTROL, uc.reg_read(UC_ARM_REG_CONTROL) | 4)
        xpsr = words[7]
        uc.reg_write(UC_ARM_REG_XPSR_NZCVQ, xpsr & 0xF8000000)
        uc.reg_write(UC_ARM_REG_SP, sp + size + (4 if xpsr & 0x200 else 0))
        self.scs.returned(self.scs.active[-1])
        uc.reg_write(UC_ARM_REG_PC, words[6] | 1)
        self.clock.cycles += 12
        self.clock.ticks += 12 * self.ticks_per_cycle
