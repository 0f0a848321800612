"""STM32F103 GPIO ports (RM0008 §9.2) and AFIO (§9.4).

Cross-checked with CMSIS stm32f10x.h: GPIOA 0x40010800, GPIOB 0x40010C00, GPIOC 0x40011000,
AFIO 0x40010000; CRL/CRH reset 0x44444444 (every pin a floating input), ODR reset 0, BSRR
set bits 15:0 / reset bits 31:16 (set wins), BRR reset bits 15:0; AFIO_MAPR CAN_REMAP bits
14:13 (0b10 = CAN RX/TX on PB8/PB9), SWJ_CFG bits 26:24 write-only (read as 0).

A pin's 4-bit configuration is CNF[1:0] MODE[1:0]: MODE 0 = input, otherwise output; for an
output CNF bit 1 selects the alternate function (the peripheral drives the pin). Models that
sit on a pin ask `pin_mode()` and listen to `watch()` for the output level.
"""

from mmio_bus import Peripheral


class GpioPort(Peripheral):
    size = 0x400

    def __init__(self, name, base, rcc, enable_bit):
        self.name, self.base = name, base
        self.rcc, self.enable_bit = rcc, enable_bit
        self.inputs = 0xFFFF  # external levels seen on input pins (pulled up by default)
        self.watchers = []  # (pin, callback(level))
        self.reset()

    def reset(self):
        self.cr = [0x44444444, 0x44444444]
        self.odr = 0

    def clocked(self):
        return self.rcc.apb2_enabled(self.enable_bit)

    def pin_config(self, pin):
        return (self.cr[pin // 8] >> (4 * (pin % 8))) & 0xF

    def pin_mode(self, pin):
        """'input', 'output' (GPIO push-pull/open-drain) or 'af' (alternate function output)."""
        cfg = self.pin_config(pin)
        if cfg & 3 == 0:
            return "input"
        return "af" if cfg & 8 else "output"

    def output_level(self, pin):
        """The level the port drives on a GPIO output pin, None if the port does not drive it."""
        return (self.odr >> pin) & 1 if self.pin_mode(pin) == "output" else None

    def watch(self, pin, callback):
        self.watchers.append((pin, callback))

    def _set(self, odr, cr=None):
        before = [self.output_level(pin) for pin, _ in self.watchers]
        self.odr = odr & 0xFFFF
        if cr is not None:
            self.cr = cr
        for (pin, callback), old in zip(self.watchers, before):
            new = self.output_level(pin)
            if new != old:
                callback(new)

    def read(self, offset):
        if offset in (0x00, 0x04):
            return self.cr[offset // 4]
        if offset == 0x08:
            idr = 0
            for pin in range(16):
                level = (self.odr >> pin) & 1 if self.pin_mode(pin) == "output" else (self.inputs >> pin) & 1
                idr |= level << pin
            return idr
        if offset == 0x0C:
            return self.odr
        if offset in (0x10, 0x14, 0x18):
            return 0
        raise RuntimeError(f"{self.name} read of offset 0x{offset:02X}")

    def write(self, offset, value):
        if offset in (0x00, 0x04):
            cr = list(self.cr)
            cr[offset // 4] = value
            self._set(self.odr, cr)
        elif offset == 0x0C:
            self._set(value)
        elif offset == 0x10:
            self._set((self.odr & ~(value >> 16)) | (value & 0xFFFF))
        elif offset == 0x14:
            self._set(self.odr & ~(value & 0xFFFF))
        elif offset == 0x18:
            pass  # LCKR: locking is not modelled
        else:
            raise RuntimeError(f"{self.name} write of offset 0x{offset:02X}")


class Afio(Peripheral):
    name = "AFIO"
    base = 0x40010000
    size = 0x400

    def __init__(self, rcc):
        self.rcc = rcc
        self.reset()

    def reset(self):
        self.regs = {0x00: 0, 0x04: 0, 0x08: 0, 0x0C: 0, 0x10: 0, 0x14: 0, 0x1C: 0}

    def clocked(self):
        return self.rcc.apb2_enabled(0)

    def can_remap(self):
        return (self.regs[0x04] >> 13) & 3

    def read(self, offset):
        if offset not in self.regs:
            raise RuntimeError(f"AFIO read of offset 0x{offset:02X}")
        return self.regs[offset] & (~(7 << 24) if offset == 0x04 else 0xFFFFFFFF)

    def write(self, offset, value):
        if offset not in self.regs:
            raise RuntimeError(f"AFIO write of offset 0x{offset:02X}")
        self.regs[offset] = value
