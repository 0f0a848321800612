"""STM32F4 USART in asynchronous mode, 8N1 (RM0090 §30.6), with a device on its pins.

Cross-checked with CMSIS stm32f407xx.h: USART1_BASE 0x40011000 (APB2ENR bit 4, IRQ 37);
SR 0x00 (reset 0x00C0: TXE bit 7, TC 6; RXNE 5, ORE 3, FE 1), DR 0x04, BRR 0x08, CR1 0x0C
(OVER8 bit 15, UE 13, M 12, TXEIE 7, TCIE 6, RXNEIE 5, TE 3, RE 2), CR2 0x10, CR3 0x14,
GTPR 0x18.

Timing: with OVER8 = 0 a bit lasts BRR cycles of PCLK2 (baud = f_PCLK / USARTDIV / 16 and
BRR holds USARTDIV × 16). The transmitter has a data register and a shift register: a byte
written while the shift register is busy waits in DR (TXE = 0); each takes 10 bit times on
the line, then reaches the device. The receiver takes the device's bytes one line-time
apart at the device's own baud rate; a byte whose rate differs from the USART's by more than
the receiver's tolerance (3 %, RM0090 §30.3.5) is lost as a framing error (counted); a byte
that completes while RXNE is still set is lost as an overrun (ORE). The interrupt is a level:
it is pending whenever an enabled condition holds and the handler is not active.

The device: `receive_byte(byte, tick, baud)` for what the MCU sends; `peek_tx()` → (ready
tick, byte, baud) or None, and `pop_tx()`, for what it sends; `update(tick)` for its own time.
"""

from mmio_bus import Peripheral
from virtual_clock import TICK_HZ, ticks_per

TXE, TC, RXNE, ORE, FE = 0x80, 0x40, 0x20, 0x08, 0x02
UE, TXEIE, TCIE, RXNEIE, TE, RE, OVER8 = 1 << 13, 1 << 7, 1 << 6, 1 << 5, 1 << 3, 1 << 2, 1 << 15


class Usart(Peripheral):
    size = 0x400

    def __init__(self, name, base, clock, rcc, enable_bit, pclk_hz, irq, scs, pins_routed):
        self.name, self.base, self.clock, self.rcc = name, base, clock, rcc
        self.enable_bit, self.pclk_hz, self.irq, self.scs = enable_bit, pclk_hz, irq, scs
        self.pins_routed = pins_routed
        self.device = None
        self.violations = []
        self.framing_errors = 0
        self.overruns = 0
        self.reset()

    def reset(self):
        self.sr = TXE | TC
        self.dr_rx = 0
        self.brr = self.cr1 = self.cr2 = self.cr3 = self.gtpr = 0
        self.tx_hold = None  # byte waiting in DR
        self.tx_shift = None  # (byte, completion tick)
        self.rx_line_free = 0  # tick at which the RX line is free for the next byte

    def clocked(self):
        return self.rcc.apb2_enabled(self.enable_bit)

    def baud(self):
        return self.pclk_hz() / self.brr if self.brr else 0

    def _frame_ticks(self):
        return 10 * self.brr * ticks_per(self.pclk_hz())

    # --- time ---
    def next_event_tick(self):
        events = []
        if self.tx_shift is not None:
            events.append(self.tx_shift[1])
        nxt = self._next_rx()
        if nxt is not None:
            events.append(nxt[0])
        return min(events) if events else None

    def _next_rx(self):
        if self.device is None:
            return None
        head = self.device.peek_tx()
        if head is None:
            return None
        ready, byte, baud = head
        return max(ready, self.rx_line_free) + 10 * TICK_HZ // baud, byte, baud

    def update(self):
        now = self.clock.ticks
        if self.device is not None:
            self.device.update(now)
        while True:
            tx_at = self.tx_shift[1] if self.tx_shift is not None else None
            rx = self._next_rx()
            rx_at = rx[0] if rx is not None else None
            if tx_at is not None and tx_at <= now and (rx_at is None or tx_at <= rx_at):
                self._tx_done(tx_at)
            elif rx_at is not None and rx_at <= now:
                self.device.pop_tx()
                self.rx_line_free = rx_at
                self._rx_byte(rx[1], rx[2])
            else:
                break
        self._irq()

    def _tx_done(self, tick):
        byte, _ = self.tx_shift
        self.tx_shift = None
        if self.device is not None and self.pins_routed():
            self.device.receive_byte(byte, tick, self.baud())
        if self.tx_hold is not None:
            self.tx_shift = (self.tx_hold, tick + self._frame_ticks())
            self.tx_hold = None
            self.sr |= TXE
        else:
            self.sr |= TC

    def _rx_byte(self, byte, baud):
        if not (self.cr1 & UE and self.cr1 & RE and self.pins_routed()):
            return
        mine = self.baud()
        if not mine or abs(mine - baud) > 0.03 * baud:
            self.framing_errors += 1
            return
        if self.sr & RXNE:
            self.sr |= ORE
            self.overruns += 1
            return
        self.dr_rx = byte
        self.sr |= RXNE

    def _irq(self):
        want = ((self.cr1 & RXNEIE and self.sr & (RXNE | ORE)) or (self.cr1 & TXEIE and self.sr & TXE)
                or (self.cr1 & TCIE and self.sr & TC))
        if want and (16 + self.irq) not in self.scs.active:
            self.scs.set_irq_pending(self.irq, True)

    # --- registers ---
    def read(self, offset):
        self.update()
        if offset == 0x00:
            return self.sr
        if offset == 0x04:
            self.sr &= ~(RXNE | ORE | FE)
            return self.dr_rx
        regs = {0x08: self.brr, 0x0C: self.cr1, 0x10: self.cr2, 0x14: self.cr3, 0x18: self.gtpr}
        if offset in regs:
            return regs[offset]
        raise RuntimeError(f"{self.name} read of offset 0x{offset:02X}")

    def write(self, offset, value):
        self.update()
        if offset == 0x00:
            self.sr &= value | ~(RXNE | TC)  # RXNE and TC are rc_w0
        elif offset == 0x04:
            self._write_dr(value & 0xFF)
        elif offset == 0x08:
            if self.cr1 & UE and (self.tx_shift is not None or self.tx_hold is not None):
                self.violations.append(f"{self.name} BRR changed while transmitting")
            self.brr = value & 0xFFFF
        elif offset == 0x0C:
            if value & OVER8:
                self.violations.append(f"{self.name} OVER8 not modelled")
            self.cr1 = value & 0xBFFF
        elif offset == 0x10:
            self.cr2 = value
        elif offset == 0x14:
            self.cr3 = value
        elif offset == 0x18:
            self.gtpr = value
        else:
            raise RuntimeError(f"{self.name} write of offset 0x{offset:02X}")
        self._irq()

    def _write_dr(self, byte):
        if not (self.cr1 & UE and self.cr1 & TE):
            self.violations.append(f"{self.name} DR written with the transmitter off")
            return
        self.sr &= ~TC
        if self.tx_shift is None:
            self.tx_shift = (byte, self.clock.ticks + self._frame_ticks())
        elif self.tx_hold is None:
            self.tx_hold = byte
            self.sr &= ~TXE
        else:
            self.violations.append(f"{self.name} DR written while TXE = 0 (byte lost)")
