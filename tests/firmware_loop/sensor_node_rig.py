"""Runs one emulated sensor node on a virtual 1 Mbit/s CAN bus with a host port standing in
for the sink: SYNC every period from `sync_start_us`, frames of the node collected.

As a program it prints what the node sent and the cycle figures:
  /usr/bin/python3 tests/firmware_loop/sensor_node_rig.py <sensor_node_f103.elf> [seconds]
"""

import struct
import sys

from can_bus import CanBus, HostPort
from sensor_node_board import SensorNodeBoard
from virtual_clock import TICK_HZ, ticks_from_us

BITRATE = 1_000_000
SYNC_ID = 0x000


class SensorNodeRig:
    def __init__(self, elf_path, motion=None, who_am_i=0x71, rate_hz=100, hse_present=True):
        self.rate_hz = rate_hz
        self.board = SensorNodeBoard(elf_path, motion=motion, who_am_i=who_am_i, hse_present=hse_present)
        self.cpu = self.board.cpu
        # One emulated MCU per bus for now: the bus runs on its clock.
        self.bus = CanBus(self.cpu.clock, BITRATE)
        self.board.connect(self.bus)
        self.host = HostPort()
        self.bus.attach(self.host)
        self.syncs = []  # (tick, counter)

    def run(self, seconds, sync_start_us=200_000, sync_count=None):
        """Runs `seconds` of virtual time, sending SYNC n at sync_start + n / rate."""
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
        step = ticks_from_us(500)  # the bus and the host port advance between slices
        while self.cpu.clock.ticks < end and self.cpu.fault is None:
            self.cpu.run_until(min(end, self.cpu.clock.ticks + step))
            self.bus.update()
        return self

    def node_frames(self):
        """(end tick, id, data) of every frame the node put on the bus."""
        return [(end, can_id, data) for (_, end, sender, can_id, data) in self.bus.log if sender == 0]


def main():
    elf = sys.argv[1]
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 0.5
    rig = SensorNodeRig(elf).run(seconds)
    for end, can_id, data in rig.node_frames():
        print(f"{end / TICK_HZ * 1e3:10.3f} ms  id 0x{can_id:03X}  {data.hex()}")
    print(f"fault: {rig.cpu.fault}; violations: {rig.board.all_violations()}; cycles {rig.cpu.clock.cycles}")


if __name__ == "__main__":
    main()
