"""The body network emulated whole: N sensor-node images and the sink image on one virtual
1 Mbit/s CAN bus, the sink's ESP8266 model dialling a real host (mocapd's sink port).

The sink sends SYNC and CONFIG itself, so the rig's host port stays silent; the scheduler is
SensorBusRig's (lock-step, 50 us steps, never past the bus's next event).

As a program it boots the network against a TCP listener of its own, runs it and prints the
sink's cycle figures (docs/firmware.md, "Sink duty cycle"):
  /usr/bin/python3 tests/firmware_loop/sink_bus_rig.py <sink_node_f407.elf> <sensor_node_f103.elf>... [--seconds S]
"""

import argparse
import socket

from sensor_node_rig import SensorBusRig
from sink_node_board import SinkNodeBoard
from virtual_clock import TICK_HZ, ticks_from_us

SINK_SLICE = 1600  # 9.5 us at 168 MHz: less than one byte time at 921600 baud (10.85 us)


class SinkBusRig(SensorBusRig):
    def __init__(self, sink_elf, node_elfs, host_address, motions=None):
        super().__init__(node_elfs, motions)
        self.sink = SinkNodeBoard(sink_elf, host_address)
        # The sink's interrupts come from the bus (delivered between steps, taken at the start
        # of the next run) and from the USART (a timed model: it ends a slice at each event it
        # knows of when the slice starts). An event created inside a slice (a byte queued by
        # the ESP8266 model in answer to a register access) is seen at the slice's end: with
        # 8400-instruction slices several received bytes landed at once and all but one were
        # lost as overruns, which silicon would not do. Slices shorter than one byte time keep
        # that to one byte, delivered at most 9.5 us late, and still spare the host most of the
        # per-slice overhead of a CPU that polls at 168 MHz.
        self.sink.cpu.slice = SINK_SLICE
        self.sink.connect(self.bus)

    def cpus(self):
        return super().cpus() + [self.sink.cpu]

    def fault(self):
        return super().fault() or (f"sink: {self.sink.cpu.fault}" if self.sink.cpu.fault else None)

    def run_for(self, seconds, until=None):
        return self.advance(self.clock.ticks + ticks_from_us(int(seconds * 1e6)), until)

    def sink_frames(self):
        """(end tick, id, data) of every frame the sink put on the bus."""
        index = len(self.bus.nodes) - 1
        return [(end, can_id, data) for (_, end, sender, can_id, data) in self.bus.log if sender == index]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("sink_elf")
    ap.add_argument("node_elfs", nargs="+")
    ap.add_argument("--seconds", type=float, default=1.5)
    args = ap.parse_args()
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    rig = SinkBusRig(args.sink_elf, args.node_elfs, srv.getsockname())
    rig.run_for(args.seconds)
    print(f"fault: {rig.fault()}; sink violations: {rig.sink.all_violations()}")
    print(f"sink: {rig.sink.cpu.clock.cycles} cycles in {rig.clock.ticks / TICK_HZ:.3f} s; "
          f"frames on the bus {len(rig.bus.log)}, by the sink {len(rig.sink_frames())}")


if __name__ == "__main__":
    main()
