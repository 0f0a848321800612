"""STM32F4 GPIO ports (RM0090 §8.4).

Cross-checked with CMSIS stm32f407xx.h: GPIOA 0x40020000, GPIOB 0x40020400, GPIOD 0x40020C00
(0x400 apart, AHB1ENR bit = port index); MODER at 0x00 (2 bits per pin: 00 input, 01 output,
10 alternate function, 11 analog; reset 0xA8000000 for port A, 0x00000280 for port B, 0
otherwise: the debug pins), OTYPER 0x04, OSPEEDR 0x08, PUPDR 0x0C, IDR 0x10, ODR 0x14, BSRR
0x18 (set bits 15:0, reset 31:16, set wins), LCKR 0x1C, AFRL 0x20, AFRH 0x24 (4 bits per pin).
"""

from mmio_bus import Peripheral

MODER_RESET = {0: 0xA8000000, 1: 0x00000280}
OSPEEDR_RESET = {1: 0x000000C0}
PUPDR_RESET = {0: 0x64000000, 1: 0x00000100}


class GpioPort(Peripheral):
    size = 0x400

    def __init__(self, name, index, rcc):
        self.name, self.index = name, index
        self.base = 0x40020000 + 0x400 * index
        self.rcc = rcc
        self.inputs = 0xFFFF
        self.reset()

    def reset(self):
        self.regs = {0x00: MODER_RESET.get(self.index, 0), 0x04: 0, 0x08: OSPEEDR_RESET.get(self.index, 0),
                     0x0C: PUPDR_RESET.get(self.index, 0), 0x14: 0, 0x1C: 0, 0x20: 0, 0x24: 0}

    def clocked(self):
        return self.rcc.ahb1_enabled(self.index)

    def pin_mode(self, pin):
        """'input', 'output', 'af' or 'analog'."""
        return ("input", "output", "af", "analog")[(self.regs[0x00] >> (2 * pin)) & 3]

    def alternate(self, pin):
        """The alternate function number selected for `pin` (meaningful in 'af' mode)."""
        return (self.regs[0x20 + 4 * (pin >> 3)] >> (4 * (pin & 7))) & 0xF

    def output_level(self, pin):
        return (self.regs[0x14] >> pin) & 1 if self.pin_mode(pin) == "output" else None

    def read(self, offset):
        if offset == 0x10:
            out = {p for p in range(16) if self.pin_mode(p) == "output"}
            return sum(((self.regs[0x14] if p in out else self.inputs) >> p & 1) << p for p in range(16))
        if offset == 0x18:
            return 0  # BSRR is write-only
        if offset in self.regs:
            return self.regs[offset]
        raise RuntimeError(f"{self.name} read of offset 0x{offset:02X}")

    def write(self, offset, value):
        if offset == 0x18:
            self.regs[0x14] = ((self.regs[0x14] & ~(value >> 16)) | value) & 0xFFFF
        elif offset == 0x14:
            self.regs[0x14] = value & 0xFFFF
        elif offset in self.regs:
            self.regs[offset] = value
        else:
            raise RuntimeError(f"{self.name} write of offset 0x{offset:02X}")
