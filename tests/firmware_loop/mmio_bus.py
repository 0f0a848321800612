"""Peripheral address space of an emulated MCU.

Each model is a `Peripheral` with a base address, a size and 32-bit register read/write
methods. The bus maps the 4 KiB pages the models occupy into unicorn as MMIO, splits byte and
half-word accesses into their word (read-modify-write, as the bus matrix does for registers
that allow it) and gates every access on the model's RCC clock enable: with the clock off,
writes are ignored and reads return 0, as on silicon (RM0008 §7.3.7). An access to an address
no model claims stops the emulation with the address and the PC (on silicon a bus fault).
"""

from unicorn.arm_const import UC_ARM_REG_PC

PAGE = 0x1000


class Peripheral:
    name = "peripheral"
    base = 0
    size = 0x400

    def clocked(self):
        return True

    def read(self, offset):
        raise NotImplementedError

    def write(self, offset, value):
        raise NotImplementedError


class BusError(Exception):
    pass


class MmioBus:
    def __init__(self, uc):
        self.uc = uc
        self.peripherals = []
        self.error = None
        self._pages = set()
        self._cache = {}  # address -> peripheral

    def attach(self, peripheral):
        self.peripherals.append(peripheral)
        first = peripheral.base & ~(PAGE - 1)
        last = (peripheral.base + peripheral.size - 1) & ~(PAGE - 1)
        for page in range(first, last + PAGE, PAGE):
            if page not in self._pages:
                self._pages.add(page)
                self.uc.mmio_map(page, PAGE, self._read, page, self._write, page)

    def _find(self, address):
        p = self._cache.get(address)
        if p is None:
            p = next((p for p in self.peripherals if p.base <= address < p.base + p.size), None)
            if p is not None:
                self._cache[address] = p
        return p

    def _fail(self, what, address):
        pc = self.uc.reg_read(UC_ARM_REG_PC)
        if self.error is None:
            self.error = f"{what} at 0x{address:08X} (PC 0x{pc:08X}): no model"
        self.uc.emu_stop()

    def _read(self, uc, offset, size, page):
        address = page + offset
        p = self._find(address)
        if p is None:
            self._fail("read", address)
            return 0
        if not p.clocked():
            return 0
        word = address & ~3
        value = p.read(word - p.base) & 0xFFFFFFFF
        shift = 8 * (address - word)
        return (value >> shift) & ((1 << (8 * size)) - 1)

    def _write(self, uc, offset, size, value, page):
        address = page + offset
        p = self._find(address)
        if p is None:
            self._fail("write", address)
            return
        if not p.clocked():
            return
        word = address & ~3
        if size == 4:
            p.write(word - p.base, value & 0xFFFFFFFF)
            return
        write_bytes = getattr(p, "write_bytes", None)
        if write_bytes is not None:  # registers with byte-wise semantics (NVIC priorities)
            write_bytes(address - p.base, size, value)
            return
        shift = 8 * (address - word)
        mask = ((1 << (8 * size)) - 1) << shift
        old = p.read(word - p.base)
        p.write(word - p.base, (old & ~mask) | ((value << shift) & mask))
