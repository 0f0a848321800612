"""Runs one emulated sensor node on a virtual 1 Mbit/s CAN bus with a host port standing in
for the sink: SYNC every period from `sync_start_us`, frames of the node collected.

As a program it prints what the node sent and the cycle figures:
  /usr/bin/python3 tests/firmware_loop/sensor_node_rig.py <sensor_node_f103.elf> [seconds]
"""

import struct
import sys

from can_bus import CanBus, HostPort
from sensor_node_board import SensorNodeBoard
from virtual_clock import TICK_HZ, Clock, ticks_from_us

BITRATE = 1_000_000
SYNC_ID = 0x000


class SensorBusRig:
    """N emulated sensor nodes on one 1 Mbit/s bus with a host port standing in for the sink.

    Every CPU runs on its own virtual clock; a common scheduler steps them all to the same
    instant, at most `STEP_US` of virtual time at a time and never past the bus's next event
    (a frame's end, a queued frame's start), then runs the bus up to that instant (the bus's
    clock is that instant: every node has reached it, to within one slice of instructions).
    A frame therefore reaches its receivers at its end; a frame a node requests is seen by
    the bus at the next step, with the tick it was requested at, so arbitration is decided as
    on the wires."""

    STEP_US = 50

    def __init__(self, elf_paths, motions=None, who_am_i=0x71, rate_hz=100, hse_present=True):
        self.rate_hz = rate_hz
        motions = motions or [None] * len(elf_paths)
        self.boards = [SensorNodeBoard(elf, motion=m, who_am_i=who_am_i, hse_present=hse_present)
                       for elf, m in zip(elf_paths, motions)]
        self.clock = Clock()
        self.bus = CanBus(self.clock, BITRATE)
        for board in self.boards:
            board.connect(self.bus)
        self.host = HostPort()
        self.host_index = self.bus.attach(self.host)
        self.syncs = []  # (tick, counter)

    def fault(self):
        return next((f"node {i}: {b.cpu.fault}" for i, b in enumerate(self.boards) if b.cpu.fault), None)

    def run(self, seconds, sync_start_us=200_000, sync_count=None):
        """Runs to `seconds` of virtual time, sending SYNC n at sync_start + n / rate."""
        period = TICK_HZ // self.rate_hz
        end = ticks_from_us(int(seconds * 1_000_000))
        start = ticks_from_us(sync_start_us)
        n = len(self.syncs)
        while True:
            tick = start + n * period
            if tick >= end or (sync_count is not None and n >= sync_count):
                break
            self.host.send(tick, SYNC_ID, struct.pack("<I", n))
            self.syncs.append((tick, n))
            n += 1
        return self.advance(end)

    def cpus(self):
        return [board.cpu for board in self.boards]

    def advance(self, end, until=None):
        """Steps every CPU and the bus to tick `end` (or until `until()` holds, checked per step)."""
        step = ticks_from_us(self.STEP_US)
        cpus = self.cpus()
        while self.clock.ticks < end and self.fault() is None and not (until and until()):
            target = min(end, self.clock.ticks + step)
            if self.bus.next_event is not None and self.clock.ticks < self.bus.next_event < target:
                target = self.bus.next_event  # a frame ends there: its receivers get it on time
            for cpu in cpus:
                cpu.run_until(target)
            self.clock.ticks = target
            self.bus.update()
        return self

    def node_frames(self, index=0):
        """(end tick, id, data) of every frame node `index` put on the bus."""
        return [(end, can_id, data) for (_, end, sender, can_id, data) in self.bus.log if sender == index]


class SensorNodeRig(SensorBusRig):
    """One node alone on the bus."""

    def __init__(self, elf_path, motion=None, **kwargs):
        super().__init__([elf_path], [motion], **kwargs)
        self.board = self.boards[0]
        self.cpu = self.board.cpu


def main():
    elf = sys.argv[1]
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
    rig = SensorNodeRig(elf).run(seconds)
    for end, can_id, data in rig.node_frames():
        print(f"{end / TICK_HZ * 1e3:10.3f} ms  id 0x{can_id:03X}  {data.hex()}")
    print(f"fault: {rig.fault()}; violations: {rig.board.all_violations()}; cycles {rig.cpu.clock.cycles}")


if __name__ == "__main__":
    main()
