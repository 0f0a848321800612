"""Several sensor-node images on one virtual CAN bus (docs/firmware.md, "Firmware in the loop"):
three nodes (ids 1, 2, 3: FIRMWARE_F103_ELF and FIRMWARE_F103_NODE_ELFS, the images the build
produces with MOCAP_SENSOR_NODE_IDS) sampling on the SYNCs of a host port that stands in for
the sink; a node reset in the middle of the stream; a disturbed bus that drives a node's CAN
controller bus-off. Virtual time only: nothing here depends on the host's speed."""

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from can_bus import frame_bits  # noqa: E402
from mpu9250_model import ACCEL_LSB_PER_G, GYRO_LSB_PER_DPS, Motion  # noqa: E402
from sensor_node_rig import SensorBusRig, SensorNodeRig  # noqa: E402
from virtual_clock import TICK_HZ, ticks_from_us  # noqa: E402
from wire_decode import (DECODE, ERRF_CAN_BUS, ERRF_RESET, STATE_RUNNING, decode,  # noqa: E402
                         samples_by_counter)

ELFS = [os.environ.get("FIRMWARE_F103_ELF", "")] + os.environ.get("FIRMWARE_F103_NODE_ELFS", "").split(";")
RATE_HZ = 100
PERIOD = TICK_HZ // RATE_HZ
SYNC_START_US = 170_000  # after the nodes' 144 ms MPU-9250 / AK8963 start-up
MOTIONS = [
    Motion(accel_g=(0.12, -0.25, 0.96), gyro_dps=(10.0, -20.0, 90.0), mag_ut=(21.0, -6.0, -39.0)),
    Motion(accel_g=(-0.5, 0.1, 0.85), gyro_dps=(-150.0, 3.0, 0.5), mag_ut=(-12.0, 18.0, -40.0)),
    Motion(accel_g=(0.0, 0.99, 0.05), gyro_dps=(0.0, 0.0, -300.0), mag_ut=(30.0, 2.0, -35.0)),
]


@pytest.fixture(scope="module", autouse=True)
def inputs():
    if len(ELFS) != 3 or not all(os.path.isfile(e) for e in ELFS) or not os.access(DECODE, os.X_OK):
        pytest.fail(f"three sensor-node images (FIRMWARE_F103_ELF, FIRMWARE_F103_NODE_ELFS: {ELFS!r}) and "
                    f"CAN_FRAME_DECODE ({DECODE!r}) must name the built files")


def expected_counts(motion):
    return ([round(a * ACCEL_LSB_PER_G[3]) for a in motion.accel_g],
            [round(w * GYRO_LSB_PER_DPS[3]) for w in motion.gyro_dps])


def check_values(samples, motion, node):
    """Every sample frame carries exactly the counts of the node's own sensor."""
    accel, gyro = expected_counts(motion)
    for counter, s in samples.items():
        if "ACCEL" in s:
            assert s["ACCEL"] == accel, (node, counter, s)
        if "GYRO" in s:
            assert s["GYRO"] == gyro, (node, counter, s)
        if "MAG" in s:
            assert all(abs(m * 0.15 - t) <= 0.15 + 1e-9 for m, t in zip(s["MAG"], motion.mag_ut)), (node, counter)


def sync_end_ticks(rig):
    return {int.from_bytes(data[:4], "little"): end
            for (_, end, sender, can_id, data) in rig.bus.log if sender == rig.host_index and can_id == 0}


def test_three_nodes_share_the_bus():
    syncs = 6
    rig = SensorBusRig(ELFS, MOTIONS, rate_hz=RATE_HZ)
    rig.run(SYNC_START_US / 1e6 + (syncs + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=syncs)
    assert rig.fault() is None, rig.fault()
    for board in rig.boards:
        assert board.all_violations() == []
        assert board.cpu.resets == 0
        assert board.led_on()
    assert rig.bus.errors == [], "a clean bus: every frame acknowledged"

    sync_end = sync_end_ticks(rig)
    assert sorted(sync_end) == list(range(syncs))
    worst_latency = 0
    for index, motion in enumerate(MOTIONS):
        frames = rig.node_frames(index)
        lines = decode(frames)
        assert not [l for l in lines if l[0] == "ERROR"], lines
        assert {int(l[1]) for l in lines if l[0] in ("ACCEL", "GYRO", "MAG", "STATUS")} == {index + 1}
        samples = samples_by_counter(lines)
        assert sorted(samples) == list(range(syncs)), (index, sorted(samples))
        assert all(len(s) == 3 for s in samples.values()), "zero frames lost"
        check_values(samples, motion, index + 1)
        statuses = [l for l in lines if l[0] == "STATUS"]
        assert int(statuses[-1][2]) == STATE_RUNNING, statuses
        # Every sample is on the bus before the next SYNC: its last frame's end after its SYNC's.
        for (end, _, data), line in zip(frames, lines):
            if line[0] in ("ACCEL", "GYRO", "MAG"):
                latency = end - sync_end[int(line[2])]
                assert 0 < latency < PERIOD, (index, line, latency)
                worst_latency = max(worst_latency, latency)

    # Bus load per SYNC period: the bits every frame took on the wire (stuffing included).
    bits = sum(frame_bits(can_id, data) for (start, _, _, can_id, data) in rig.bus.log
               if start >= rig.syncs[0][0])
    load = bits / syncs / (1_000_000 / RATE_HZ)
    print(f"\nthree nodes, raw mode, {RATE_HZ} Hz at 1 Mbit/s: {bits / syncs:.0f} bits per SYNC period "
          f"({100 * load:.2f} % bus load); worst SYNC end -> sample frame end {worst_latency * 1e6 / TICK_HZ:.0f} us")


def test_a_node_reset_mid_stream_comes_back_and_the_others_lose_nothing():
    # Node 3's reset line is pulled (a loose connector, a brown-out) after the third SYNC; it
    # starts again from its reset vector, brings its MPU-9250 up again (144 ms) and joins the
    # stream at the next SYNC. Nodes 1 and 2 sample every SYNC throughout.
    syncs = 24
    rig = SensorBusRig(ELFS, MOTIONS, rate_hz=RATE_HZ)
    reset_us = SYNC_START_US + 25_000
    rig.run(reset_us / 1e6, sync_start_us=SYNC_START_US, sync_count=syncs)
    rig.boards[2].cpu.pin_reset()
    reset_tick = rig.clock.ticks
    rig.run(SYNC_START_US / 1e6 + (syncs + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=syncs)
    assert rig.fault() is None, rig.fault()
    assert [b.cpu.resets for b in rig.boards] == [0, 0, 1]
    assert all(b.all_violations() == [] for b in rig.boards)
    assert rig.bus.errors == []

    for index in (0, 1):
        samples = samples_by_counter(decode(rig.node_frames(index)))
        assert sorted(samples) == list(range(syncs)), (index, sorted(samples))
        assert all(len(s) == 3 for s in samples.values())
        check_values(samples, MOTIONS[index], index + 1)

    frames = rig.node_frames(2)
    lines = decode(frames)
    before = samples_by_counter([l for (end, _, _), l in zip(frames, lines) if end <= reset_tick])
    after_frames = [(f, l) for f, l in zip(frames, lines) if f[0] > reset_tick]
    after = samples_by_counter([l for _, l in after_frames])
    assert sorted(before) == [0, 1, 2], sorted(before)
    # Back within the MPU-9250's start-up plus a period or two, then every SYNC to the end.
    assert after, "node 3 never came back"
    first = min(after)
    sync_tick = dict((n, t) for t, n in rig.syncs)
    back_after_ms = (sync_tick[first] - reset_tick) * 1000 / TICK_HZ
    assert back_after_ms < 200, back_after_ms
    assert sorted(after) == list(range(first, syncs)), sorted(after)
    assert all(len(s) == 3 for s in after.values())
    check_values(after, MOTIONS[2], 3)
    # It says it was reset, in its first STATUS after it, and nothing it sent after the reset
    # belongs to a SYNC it was not running for.
    statuses = [l for _, l in after_frames if l[0] == "STATUS"]
    assert statuses and int(statuses[0][3]) & ERRF_RESET, statuses
    assert all(sync_tick[c] > reset_tick for c in after)
    print(f"\nnode 3 reset {(reset_tick - ticks_from_us(SYNC_START_US)) * 1000 / TICK_HZ:.1f} ms after the first "
          f"SYNC: sampling again from SYNC {first}, {back_after_ms:.0f} ms after the reset; nodes 1 and 2: "
          f"{syncs} of {syncs} samples")


def test_a_disturbed_bus_drives_the_node_bus_off_and_it_recovers():
    # A disturbance destroys every frame on the wires for 12 ms from just after SYNC 3 (whose
    # 70-bit frame ends 70 us after it starts): the node's sample frames of SYNC 3 fail, its
    # transmit error counter climbs by 8 per attempt, the controller goes bus-off and recovers
    # by itself (ABOM) after 128 x 11 recessive bits, again and again while the disturbance
    # lasts; SYNC 4 is destroyed on the wires. The node samples again on the SYNCs after.
    syncs = 9
    rig = SensorNodeRig(ELFS[0], motion=MOTIONS[0], rate_hz=RATE_HZ)
    start = ticks_from_us(SYNC_START_US + 80) + 3 * PERIOD
    end = start + ticks_from_us(12_000)
    rig.bus.error_windows.append((start, end))
    rig.run(SYNC_START_US / 1e6 + (syncs + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=syncs)
    assert rig.fault() is None, rig.fault()
    assert rig.board.all_violations() == []
    assert rig.board.can.bus_offs >= 1, "the disturbance must take the controller bus-off"
    assert rig.bus.errors and all(start <= t < end for t, _, _ in rig.bus.errors)

    lines = decode(rig.node_frames())
    samples = samples_by_counter(lines)
    check_values(samples, MOTIONS[0], 1)
    sync_tick = dict((n, t) for t, n in rig.syncs)
    after = [n for n in range(syncs) if sync_tick[n] >= end]
    assert after and all(n in samples and len(samples[n]) == 3 for n in after), (after, sorted(samples))
    lost = [n for n in range(syncs) if start <= sync_tick[n] < end]
    assert not [n for n in lost if n in samples], "a SYNC destroyed on the wires cannot have a sample"
    statuses = [l for l in lines if l[0] == "STATUS"]
    assert any(int(l[3]) & ERRF_CAN_BUS for l in statuses), "the node reports the bus errors"
    assert int(statuses[-1][2]) == STATE_RUNNING, statuses
    print(f"\ndisturbed 12 ms: {len(rig.bus.errors)} error frames, bus-off {rig.board.can.bus_offs} times; "
          f"samples of SYNCs {sorted(samples)} of 0..{syncs - 1}")
