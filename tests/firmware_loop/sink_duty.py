"""The sink image's duty cycle per SYNC period at 168 MHz, on virtual time (one instruction =
one cycle), with the sensor-node images on the bus and a TCP listener standing in for mocapd.

The sink polls: its main loop calls sink_node_poll() without pause, so every period holds
168 MHz / rate cycles whatever it does. The work is what is not idle polling: a code hook on
the call of sink_node_poll in main() counts loop iterations; the cost of one idle iteration is
the fewest cycles per iteration seen over any 50 us step (a step with nothing to do); a
period's work = its cycles - its iterations x that cost (interrupt handlers included).
Periods run from one SYNC request of the sink to the next (sampled at the 50 us steps).

  /usr/bin/python3 tests/firmware_loop/sink_duty.py <sink_node_f407.elf> <sensor_node_f103.elf>... [--seconds S]
"""

import argparse
import socket
import subprocess
import threading

from unicorn import UC_HOOK_CODE

from sink_bus_rig import SinkBusRig
from virtual_clock import TICK_HZ, ticks_from_us


def poll_call_address(elf):
    """Address of `bl <sink_node_poll>` in main() (the loop head), from the disassembly."""
    text = subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf], check=True,
                          capture_output=True, text=True).stdout
    in_main = False
    for line in text.splitlines():
        if line.endswith("<main>:"):
            in_main = True
        elif in_main and "<sink_node_poll>" in line and "bl" in line:
            return int(line.split(":")[0], 16)
        elif in_main and not line.strip():
            break
    raise RuntimeError("no call of sink_node_poll in main()")


def drain(server):
    conn, _ = server.accept()
    while conn.recv(65536):
        pass


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("sink_elf")
    ap.add_argument("node_elfs", nargs="+")
    ap.add_argument("--seconds", type=float, default=1.2)
    args = ap.parse_args()
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    threading.Thread(target=drain, args=(server,), daemon=True).start()
    rig = SinkBusRig(args.sink_elf, args.node_elfs, server.getsockname())
    rig.sink.esp.join_us = 100_000
    iterations = [0]

    def count(*_):
        iterations[0] += 1

    address = poll_call_address(args.sink_elf)
    rig.sink.cpu.uc.hook_add(UC_HOOK_CODE, count, begin=address, end=address)
    cpu = rig.sink.cpu
    samples = []  # (tick, cycles, iterations) after each step
    end = ticks_from_us(int(args.seconds * 1e6))
    while rig.clock.ticks < end and rig.fault() is None:
        rig.advance(min(end, rig.clock.ticks + ticks_from_us(rig.STEP_US)))
        samples.append((rig.clock.ticks, cpu.clock.cycles, iterations[0]))
    assert rig.fault() is None, rig.fault()
    idle = min((c1 - c0) / (i1 - i0) for (_, c0, i0), (_, c1, i1) in zip(samples, samples[1:]) if i1 - i0 >= 10)
    syncs = [t for t, _, can_id in rig.sink.can.tx_log if can_id == 0x000]
    # From the 20th SYNC on (the nodes are up): the Wi-Fi set-up, the connection and streaming.
    syncs = syncs[20:]
    work = []
    for a, b in zip(syncs, syncs[1:]):
        s0 = next(s for s in samples if s[0] >= a)
        s1 = next(s for s in samples if s[0] >= b)
        work.append((s1[1] - s0[1]) - (s1[2] - s0[2]) * idle)
    period = 168_000_000 // 100
    print(f"idle loop iteration {idle:.1f} cycles; {len(work)} SYNC periods of {period} cycles "
          f"(100 Hz, {len(args.node_elfs)} nodes, raw) from {syncs[0] / TICK_HZ:.3f} s")
    print(f"work per period: mean {sum(work) / len(work):.0f}, max {max(work):.0f} cycles; "
          f"duty mean {100 * sum(work) / len(work) / period:.2f} %, worst {100 * max(work) / period:.2f} %")


if __name__ == "__main__":
    main()
