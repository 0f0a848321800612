"""bxCAN controller (RM0008 §24, registers §24.9; the F407's is the same, RM0090 §32).

Cross-checked with CMSIS stm32f10x.h: CAN1_BASE 0x40006400; MCR INRQ bit 0, SLEEP 1, TXFP 2,
RFLM 3, NART 4, ABOM 6, reset 0x00010002; MSR INAK bit 0, SLAK 1, reset 0x00000C02; TSR
RQCP0 bit 0, TXOK0 1, TERR0 3, CODE bits 25:24, TME0..2 bits 26..28, reset 0x1C000000; RF0R
FMP0 bits 1:0, FULL0 3, FOVR0 4, RFOM0 5; IER FMPIE0 bit 1; ESR EPVF bit 1, BOFF 2, TEC bits
23:16; BTR BRP bits 9:0, TS1 19:16, TS2 22:20, reset 0x01230000; mailboxes at 0x180, FIFOs at
0x1B0, FMR 0x200 (FINIT bit 0, reset 0x2A1C0E01), FM1R 0x204, FS1R 0x20C, FFA1R 0x214,
FA1R 0x21C, filter banks at 0x240 (14 on the F103).

Modes: sleep after reset (SLAK); INRQ enters initialisation (INAK); clearing INRQ and SLEEP
joins the bus after 11 recessive bits at the configured bit rate. BTR is writable only in
initialisation, filter banks only while FINIT is set or the bank is inactive. Three TX
mailboxes: by request order with TXFP, else lowest identifier first; a frame nobody
acknowledges (wrong bit rate, TX pin not routed) raises TEC by 8 and is retried
(NART = 0): error-passive above 127, bus-off above 255, recovered after 128 x 11 recessive bits
with ABOM. RX FIFO 0 and 1, three frames each, filters in both scales and modes; with FMPIE0
a non-empty FIFO 0 pends its interrupt.
"""

from mmio_bus import Peripheral
from virtual_clock import ticks_per

INRQ, SLEEP, TXFP, RFLM, NART, ABOM = 1, 2, 4, 8, 16, 64


class BxCan(Peripheral):
    name = "CAN1"
    size = 0x400

    def __init__(self, base, clock, rcc, enable_bit, pclk_hz, pins_routed, irq_fifo0, scs, banks):
        self.base, self.clock, self.rcc, self.enable_bit = base, clock, rcc, enable_bit
        self.pclk_hz, self.pins_routed = pclk_hz, pins_routed
        self.irq_fifo0, self.scs, self.banks = irq_fifo0, scs, banks
        self.bus = None
        self.reset()

    def reset(self):
        self.mcr = 0x00010002
        self.inak, self.slak = False, True
        self.join_at = None
        self.tsr_flags = 0
        self.ier = 0
        self.tec = self.rec = 0
        self.bus_off_until = None
        self.bus_offs = 0  # times the controller went bus-off since reset
        self.btr = 0x01230000
        self.mailbox = [[0, 0, 0, 0] for _ in range(3)]
        self.request_tick = [0, 0, 0]
        self.fifo = [[], []]
        self.fovr = [False, False]
        self.fmr, self.fm1r, self.fs1r, self.ffa1r, self.fa1r = 0x2A1C0E01, 0, 0, 0, 0
        self.fr = [[0, 0] for _ in range(self.banks)]
        self.tx_log = []  # (request tick, mailbox, identifier) per TXRQ
        self.violations = []

    def clocked(self):
        return self.rcc.apb1_enabled(self.enable_bit)

    # --- bit timing and mode ---
    def bit_ticks(self):
        brp = (self.btr & 0x3FF) + 1
        tq = 1 + ((self.btr >> 16) & 0xF) + 1 + ((self.btr >> 20) & 7) + 1
        return brp * tq * ticks_per(self.pclk_hz())

    def _normal(self):
        self._update_mode()
        return not self.inak and not self.slak and self.bus_off_until is None

    def _update_mode(self):
        now = self.clock.ticks
        if self.join_at is not None and now >= self.join_at:
            self.join_at = None
            self.inak = False
        if self.bus_off_until is not None and now >= self.bus_off_until:
            self.bus_off_until = None
            self.tec = self.rec = 0

    # --- bus side ---
    def _pending(self):
        return [i for i in range(3) if self.mailbox[i][0] & 1]

    def next_ready(self):
        if self.bus is not None and not self._normal():
            return None
        pending = self._pending()
        return min((self.request_tick[i] for i in pending), default=None)

    def contender(self, tick):
        if not self._normal():
            return None
        ready = [i for i in self._pending() if self.request_tick[i] <= tick]
        if not ready:
            return None
        if self.mcr & TXFP:
            i = min(ready, key=lambda m: (self.request_tick[m], m))
        else:
            i = min(ready, key=lambda m: (self.mailbox[m][0] >> 21, m))
        tir, tdtr, tdlr, tdhr = self.mailbox[i]
        dlc = min(tdtr & 0xF, 8)
        data = (tdlr | (tdhr << 32)).to_bytes(8, "little")[:dlc]
        return (i, (tir >> 21) & 0x7FF, data)

    def joined(self, bus_bit_ticks):
        return self.pins_routed() and abs(self.bit_ticks() - bus_bit_ticks) * 100 <= bus_bit_ticks

    def transmitted(self, frame, ok):
        i = frame[0]
        if ok:
            self.mailbox[i][0] &= ~1
            self.tsr_flags |= 0x3 << (8 * i)  # RQCP, TXOK
            self.tec = max(0, self.tec - 1)
            return
        self.tec += 8
        if self.tec > 255 and self.bus_off_until is None:
            self.bus_offs += 1
            # Bus-off; with ABOM it recovers after 128 occurrences of 11 recessive bits.
            self.bus_off_until = self.clock.ticks + 128 * 11 * self.bit_ticks() if self.mcr & ABOM else 1 << 62
        if self.mcr & NART:
            self.mailbox[i][0] &= ~1
            self.tsr_flags |= 0x9 << (8 * i)  # RQCP, TERR

    def receive(self, can_id, data, tick):
        if not self._normal() or not self.pins_routed():
            return
        match = self._filter(can_id << 21)
        if match is None:
            return
        fifo, fmi = match
        frame = [can_id << 21, (fmi << 8) | len(data), int.from_bytes(data[:4].ljust(4, b"\0"), "little"),
                 int.from_bytes(data[4:8].ljust(4, b"\0"), "little")]
        if len(self.fifo[fifo]) == 3:
            self.fovr[fifo] = True
            if self.mcr & RFLM:
                return
            self.fifo[fifo][-1] = frame
        else:
            self.fifo[fifo].append(frame)
        self._irq()

    def _filter(self, word):
        """(FIFO, filter match index) of the first active bank admitting a standard data frame."""
        numbers = [0, 0]
        for b in range(self.banks):
            fifo = (self.ffa1r >> b) & 1
            scale32, list_mode = (self.fs1r >> b) & 1, (self.fm1r >> b) & 1
            count = (1 if scale32 else 2) * (2 if list_mode else 1)
            if (self.fa1r >> b) & 1:
                fr1, fr2 = self.fr[b]
                hit = None
                if scale32 and not list_mode:
                    hit = 0 if ((word ^ fr1) & fr2 & ~1) == 0 else None
                elif scale32:
                    hit = next((k for k, r in enumerate((fr1, fr2)) if (r & ~1) == (word & ~1)), None)
                else:
                    half = (word >> 16) & 0xFFE0  # STID[10:0] at bits 15:5, RTR = IDE = 0
                    regs = [fr1 & 0xFFFF, fr1 >> 16, fr2 & 0xFFFF, fr2 >> 16]
                    if list_mode:
                        hit = next((k for k, r in enumerate(regs) if r == half), None)
                    else:
                        hit = next((k for k in (0, 1) if ((half ^ regs[2 * k]) & regs[2 * k + 1]) == 0), None)
                if hit is not None:
                    return fifo, numbers[fifo] + hit
            numbers[fifo] += count
        return None

    def _irq(self):
        if self.ier & 2 and self.fifo[0]:
            self.scs.set_irq_pending(self.irq_fifo0, True)

    # --- registers ---
    def _sync(self):
        if self.bus is not None:
            self.bus.update()
        self._update_mode()

    def read(self, offset):
        self._sync()
        if offset == 0x000:
            return self.mcr
        if offset == 0x004:
            return 0x00000C00 | (1 if self.inak else 0) | (2 if self.slak else 0)
        if offset == 0x008:
            tme = sum(1 << (26 + i) for i in range(3) if not self.mailbox[i][0] & 1)
            free = [i for i in range(3) if not self.mailbox[i][0] & 1]
            code = free[0] if free else 0
            return self.tsr_flags | tme | (code << 24)
        if offset in (0x00C, 0x010):
            f = (offset - 0x00C) // 4
            return len(self.fifo[f]) | (8 if len(self.fifo[f]) == 3 else 0) | (16 if self.fovr[f] else 0)
        if offset == 0x014:
            return self.ier
        if offset == 0x018:
            epvf = 2 if self.tec > 127 or self.rec > 127 else 0
            boff = 4 if self.bus_off_until is not None else 0
            return epvf | boff | (min(self.tec, 255) << 16) | (self.rec << 24)
        if offset == 0x01C:
            return self.btr
        if 0x180 <= offset < 0x1B0:
            return self.mailbox[(offset - 0x180) // 16][(offset % 16) // 4]
        if 0x1B0 <= offset < 0x1D0:
            f, reg = (offset - 0x1B0) // 16, (offset % 16) // 4
            return self.fifo[f][0][reg] if self.fifo[f] else 0
        if offset == 0x200:
            return self.fmr
        if offset in (0x204, 0x20C, 0x214, 0x21C):
            return {0x204: self.fm1r, 0x20C: self.fs1r, 0x214: self.ffa1r, 0x21C: self.fa1r}[offset]
        if 0x240 <= offset < 0x240 + 8 * self.banks:
            return self.fr[(offset - 0x240) // 8][(offset % 8) // 4]
        raise RuntimeError(f"CAN read of offset 0x{offset:03X}")

    def write(self, offset, value):
        self._sync()
        if offset == 0x000:
            self._write_mcr(value)
        elif offset == 0x008:
            self.tsr_flags &= ~(value & 0x000F0F0F)  # rc_w1 status bits
        elif offset in (0x00C, 0x010):
            f = (offset - 0x00C) // 4
            if value & 0x10:
                self.fovr[f] = False
            if value & 0x20 and self.fifo[f]:
                self.fifo[f].pop(0)
            self._irq()
        elif offset == 0x014:
            self.ier = value
            self._irq()
        elif offset == 0x018:
            pass  # LEC only
        elif offset == 0x01C:
            if self.inak:
                self.btr = value & 0xC37F03FF
            else:
                self.violations.append("BTR written outside initialisation mode (ignored)")
        elif 0x180 <= offset < 0x1B0:
            i, reg = (offset - 0x180) // 16, (offset % 16) // 4
            if self.mailbox[i][0] & 1:
                self.violations.append(f"mailbox {i} written while pending")
                return
            self.mailbox[i][reg] = value
            if reg == 0 and value & 1:
                self.request_tick[i] = self.clock.ticks
                self.tx_log.append((self.clock.ticks, i, (value >> 21) & 0x7FF))
                if not self._normal():
                    pass  # stays pending until the controller is on the bus
        elif offset == 0x200:
            self.fmr = (self.fmr & ~1) | (value & 1)
        elif offset in (0x204, 0x20C, 0x214, 0x21C):
            mask = (1 << self.banks) - 1
            setattr(self, {0x204: "fm1r", 0x20C: "fs1r", 0x214: "ffa1r", 0x21C: "fa1r"}[offset], value & mask)
        elif 0x240 <= offset < 0x240 + 8 * self.banks:
            b = (offset - 0x240) // 8
            if not self.fmr & 1 and (self.fa1r >> b) & 1:
                self.violations.append(f"filter bank {b} written while active outside FINIT (ignored)")
                return
            self.fr[b][(offset % 8) // 4] = value
        else:
            raise RuntimeError(f"CAN write of offset 0x{offset:03X}")

    def _write_mcr(self, value):
        if value & 0x8000:  # RESET: master reset, back to sleep
            self.reset()
            return
        self.mcr = value & 0x100FF
        if value & INRQ:
            self.inak, self.join_at = True, None
            self.slak = False
        elif value & SLEEP:
            self.slak, self.inak, self.join_at = True, False, None
        else:
            self.slak = False
            if self.inak and self.join_at is None:
                self.join_at = self.clock.ticks + 11 * self.bit_ticks()
