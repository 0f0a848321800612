"""Firmware in the loop: the sensor-node image the build produces (FIRMWARE_F103_ELF), run from
its reset vector on the emulated STM32F103 with its MPU-9250 and CAN bus (this directory),
its CAN frames decoded by the wire library (CAN_FRAME_DECODE, built from can_frame_decode.c).
Virtual time only: nothing here depends on the host's speed."""

import math
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mpu9250_model import ACCEL_LSB_PER_G, GYRO_LSB_PER_DPS, Motion  # noqa: E402
from sensor_node_rig import SensorNodeRig  # noqa: E402
from virtual_clock import TICK_HZ  # noqa: E402
from wire_decode import DECODE, ERRF_IMU, STATE_FAULT, STATE_RUNNING, decode  # noqa: E402

ELF = os.environ.get("FIRMWARE_F103_ELF", "")
ENCODE_CONFIG = os.environ.get("CAN_CONFIG_ENCODE", "")
RATE_HZ = 100
SYNCS = 6
SYNC_START_US = 170_000  # after the node's 144 ms MPU-9250 / AK8963 start-up
G = 9.80665


def per_sample_cycles(rig, frames_per_sample):
    """CPU cycles from each SYNC's arrival in the RX FIFO to the transmit request of the
    sample's last frame (ACCEL, GYRO, MAG, ATT: functions 2 to 5)."""
    requests = [t for t, _, can_id in rig.board.can.tx_log if 2 <= can_id >> 6 <= 5]
    sync_ends = [end for (_, end, sender, can_id, _) in rig.bus.log if can_id == 0 and sender == 1]
    cycles = []
    for end in sync_ends:
        after = [t for t in requests if t >= end][:frames_per_sample]
        assert len(after) == frames_per_sample
        cycles.append((after[-1] - end) * rig.board.rcc.hclk_hz() // TICK_HZ)
    return cycles


def report_cycles(rig, mode, frames_per_sample):
    cycles = per_sample_cycles(rig, frames_per_sample)
    period = rig.board.rcc.hclk_hz() // RATE_HZ
    print(f"\n{mode} mode: cycles per sample (SYNC in FIFO -> last frame requested): max {max(cycles)}, "
          f"mean {sum(cycles) // len(cycles)}, of {period} per SYNC period at {RATE_HZ} Hz "
          f"({100 * max(cycles) / period:.2f} %); boot to first STATUS "
          f"{min(t for t, _, _ in rig.board.can.tx_log) * 1000 // TICK_HZ} ms")
    assert max(cycles) < period, "a sample must fit its SYNC slot"


@pytest.fixture(scope="module", autouse=True)
def inputs():
    if not os.path.isfile(ELF) or not os.access(DECODE, os.X_OK) or not os.access(ENCODE_CONFIG, os.X_OK):
        pytest.fail(f"FIRMWARE_F103_ELF ({ELF!r}), CAN_FRAME_DECODE ({DECODE!r}) and CAN_CONFIG_ENCODE "
                    f"({ENCODE_CONFIG!r}) must name the built files")


def run_node(motion, who_am_i=0x71, hse_present=True, seconds=None):
    rig = SensorNodeRig(ELF, motion=motion, who_am_i=who_am_i, rate_hz=RATE_HZ, hse_present=hse_present)
    rig.run(seconds or SYNC_START_US / 1e6 + (SYNCS + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=SYNCS)
    assert rig.cpu.fault is None, rig.cpu.fault
    assert rig.board.all_violations() == []
    assert rig.cpu.resets == 0
    return rig


def test_constant_motion_arrives_as_sent():
    motion = Motion(accel_g=(0.12, -0.25, 0.96), gyro_dps=(10.0, -20.0, 90.0), mag_ut=(21.0, -6.0, -39.0))
    rig = run_node(motion)
    lines = decode(rig.node_frames())
    assert not [l for l in lines if l[0] == "ERROR"], lines

    samples = {}
    for l in lines:
        if l[0] in ("ACCEL", "GYRO", "MAG"):
            assert int(l[1]) == 1  # MOCAP_SENSOR_NODE_ID of the default build
            samples.setdefault(int(l[2]), {})[l[0]] = ([int(v) for v in l[3:6]], [float(v) for v in l[6:9]])
    assert sorted(samples) == list(range(SYNCS)), "one sample per SYNC, tagged with its counter"

    # Counts: exactly what the model's registers held (the firmware forwards them unchanged,
    # the magnetometer back in MPU axes with its factory adjustment undone to 0.15 uT/LSB).
    accel_counts = [round(a * ACCEL_LSB_PER_G[3]) for a in motion.accel_g]
    gyro_counts = [round(w * GYRO_LSB_PER_DPS[3]) for w in motion.gyro_dps]
    for counter, s in samples.items():
        assert s["ACCEL"][0] == accel_counts, counter
        assert s["GYRO"][0] == gyro_counts, counter
        for axis in range(3):
            # AK8963 raw (0.15 uT/LSB over its ASA factor), re-adjusted in integers: 1 LSB.
            assert abs(s["MAG"][0][axis] * 0.15 - motion.mag_ut[axis]) <= 0.15 + 1e-9, (counter, s["MAG"])

        # SI units through the wire library: within the quantisation (half an LSB) plus, for
        # the gyroscope, the wire library's full-scale/32768 LSB against the datasheet's
        # 16.4 LSB/(deg/s) (0.1 %, docs/firmware.md).
        for axis in range(3):
            assert abs(s["ACCEL"][1][axis] - motion.accel_g[axis] * G) <= 0.5 * G / 2048 + 1e-5
            rate = math.radians(motion.gyro_dps[axis])
            assert abs(s["GYRO"][1][axis] - rate) <= math.radians(0.5 / 16.4) + abs(rate) * 0.0011
            assert abs(s["MAG"][1][axis] - motion.mag_ut[axis]) <= 0.15 + 1e-5

    statuses = [l for l in lines if l[0] == "STATUS"]
    assert statuses and int(statuses[-1][2]) == STATE_RUNNING and int(statuses[-1][6]) == 1
    assert int(statuses[-1][3]) & ERRF_IMU == 0
    assert rig.board.led_on()
    # SysTick (exception 15) entered and returned from once per millisecond since board_init.
    ms = rig.cpu.clock.ticks * 1000 // TICK_HZ
    assert ms - 5 <= rig.cpu.exceptions_taken.get(15, 0) <= ms
    assert rig.cpu.scs.active == []

    report_cycles(rig, "raw", 3)


def test_wrong_who_am_i_sends_no_samples():
    rig = run_node(Motion(), who_am_i=0x70)
    lines = decode(rig.node_frames())
    assert not [l for l in lines if l[0] in ("ACCEL", "GYRO", "MAG", "ATT")], lines
    statuses = [l for l in lines if l[0] == "STATUS"]
    assert statuses, "the node reports its fault"
    assert all(int(l[2]) == STATE_FAULT and int(l[3]) & ERRF_IMU for l in statuses), statuses
    assert not rig.board.led_on()


def test_no_crystal_stays_off_the_bus():
    # Without the 8 MHz crystal the clock set-up stays on the 8 MHz HSI: the bit timing made
    # for a 36 MHz APB1 would give 222 kbit/s on a 1 Mbit/s bus, where every frame the node
    # starts is an error for the other nodes. The node must stay off the bus (the sink then
    # reports it lost). 1.8 s covers its start-up (1.6 s), whose waits take 9 times longer on SysTick
    # counts meant for 72 MHz.
    rig = run_node(Motion(), hse_present=False, seconds=1.8)
    assert rig.board.rcc.sysclk_hz() == 8_000_000
    assert [e for e in rig.bus.errors if e[1] == 0] == [], "the node disturbed the bus"
    assert rig.node_frames() == []


def test_sensor_lost_mid_stream_sends_no_samples():
    # Three good samples, then the MPU-9250 stops answering (MISO floats high): the 0xFF
    # bytes must not go out as samples (-1 counts would pass for real ones); the node
    # reports FAULT and will initialise the sensor again before trusting it
    # (firmware_sensor_node_test covers the return).
    rig = SensorNodeRig(ELF, motion=Motion(), rate_hz=RATE_HZ)
    rig.run(SYNC_START_US / 1e6 + 2.5 / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=SYNCS)
    rig.board.mpu.answering = False
    rig.run(SYNC_START_US / 1e6 + (SYNCS + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=SYNCS)
    assert rig.cpu.fault is None, rig.cpu.fault
    assert rig.board.all_violations() == []
    lines = decode(rig.node_frames())
    counters = sorted({int(l[2]) for l in lines if l[0] in ("ACCEL", "GYRO", "MAG")})
    assert counters == [0, 1, 2], lines
    statuses = [l for l in lines if l[0] == "STATUS"]
    assert int(statuses[-1][2]) == STATE_FAULT and int(statuses[-1][3]) & ERRF_IMU, statuses


def test_raw_attitude_mode_fits_the_sync_period():
    # The node's worst case: raw + attitude (four frames and the soft-float filter per SYNC),
    # switched on by a broadcast CONFIG as the sink sends it. A level node at rest: every ATT
    # must say level (body z along earth up) within 1 degree.
    mode_raw_attitude = 2
    out = subprocess.run([ENCODE_CONFIG, "0", str(RATE_HZ), "3", "3", str(mode_raw_attitude), "1"],
                         capture_output=True, text=True, check=True).stdout.split()
    rig = SensorNodeRig(ELF, motion=Motion(accel_g=(0.0, 0.0, 1.0), mag_ut=(21.0, -6.0, -39.0)), rate_hz=RATE_HZ)
    rig.host.send(int(SYNC_START_US * 0.95) * (TICK_HZ // 1_000_000), int(out[0], 16), bytes.fromhex(out[1]))
    rig.run(SYNC_START_US / 1e6 + (SYNCS + 0.5) / RATE_HZ, sync_start_us=SYNC_START_US, sync_count=SYNCS)
    assert rig.cpu.fault is None, rig.cpu.fault
    assert rig.board.all_violations() == []
    lines = decode(rig.node_frames())
    att = [l for l in lines if l[0] == "ATT"]
    assert sorted(int(l[2]) for l in att) == list(range(SYNCS)), lines
    for l in att:
        w, x, y, z = (float(v) for v in l[3:7])
        up_z = 1 - 2 * (x * x + y * y)  # earth-up component of the body z axis
        assert math.degrees(math.acos(max(-1.0, min(1.0, up_z)))) < 1.0, l
    assert sorted({int(l[2]) for l in lines if l[0] == "ACCEL"}) == list(range(SYNCS))
    report_cycles(rig, "raw + attitude", 4)
