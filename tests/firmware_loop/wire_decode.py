"""CAN frames from the virtual bus read by the repository's wire library, as the sink and mocapd
read them (CAN_FRAME_DECODE, built from can_frame_decode.c; its output lines are described
there)."""

import os
import subprocess

DECODE = os.environ.get("CAN_FRAME_DECODE", "")
STATE_WAITING, STATE_RUNNING, STATE_FAULT = 1, 2, 3
ERRF_IMU, ERRF_CAN_BUS, ERRF_RESET = 0x01, 0x40, 0x80


def decode(frames):
    """[fields...] per frame of (tick, id, data) triples."""
    text = "".join(f"{can_id:03X} {data.hex()}\n" for _, can_id, data in frames)
    out = subprocess.run([DECODE], input=text, capture_output=True, text=True, check=True).stdout
    return [line.split() for line in out.splitlines()]


def samples_by_counter(lines, kinds=("ACCEL", "GYRO", "MAG")):
    """{counter: {kind: [counts]}} of the sample frames among decoded lines."""
    samples = {}
    for line in lines:
        if line[0] in kinds:
            samples.setdefault(int(line[2]), {})[line[0]] = [int(v) for v in line[3:6]]
    return samples
