#!/usr/bin/env python3
"""body_real_convert.py — a real 16-IMU full-body recording without magnetometer (one CSV per
segment, the `mocap-filter --in` layout) to a mocapd raw recording on the default 15-segment
body, with a calibration for that subject made from the sensor-to-segment orientations published
with it, so that `mocapd --replay` and `mocapd --play` need no T-pose.

    /usr/bin/python3 tests/bench/body_real_convert.py DATA --out OUT
        [--frames sensor|segment] [--trunk upper_back|lower_back] [--subject 1] [--pb2-dir DIR]
    /usr/bin/python3 tests/bench/body_real_convert.py --self-test

DATA is the recording's directory: a README.md holding the published table of
`q_segment_to_sensor` (w, x, y, z; q_earth_segment = q_earth_sensor * q, segment frames after the
ISB recommendation: x anterior, y superior, z right in the anatomical position) and a directory
full_body_16/ (or DATA itself) of hip, lower_back, upper_back, head, upper_arm_*, forearm_*,
hand_*, upper_leg_*, lower_leg_*, foot_* (.csv or .csv.gz; columns t,gx,gy,gz,ax,ay,az,mx,my,mz,
s, rad/s, m/s², mag = nan). The recording used for docs/fusion.md is the full-body example of the
qmt toolbox (github.com/dlaidig/qmt, examples/full_body_example_data.mat; SPDX-FileCopyrightText:
2021 Bo Yang; SPDX-License-Identifier: MIT), converted to such CSVs without other change. Neither
the data nor its published orientations are in this repository: both are read from DATA.

Writes:
  OUT/body_real.mocapraw                        the raw recording (proto/mocap/v1/recording.proto)
  OUT/calibration/calibration-subject-N.toml    the subject's calibration (skeleton/calibration.hpp)
  OUT/play.toml                                 a config for `mocapd --config OUT/play.toml --play ...`

Mapping onto the default body (node ids 1..15 in body order, body_model.hpp): hip -> pelvis,
upper_back -> trunk, head, upper_arm/forearm/hand -> *_upper_arm/*_forearm/*_hand,
upper_leg -> *_thigh, lower_leg -> *_calf, foot -> *_foot. lower_back is dropped: the default
trunk carries the shoulders and the neck, so the thoracic sensor is the one that moves with
what hangs off it (the lumbar sensor moves mostly with the pelvis); --trunk lower_back takes it
instead.

Samples: subject N (sink 1 with subject_id_base 0), SYNC = sample index + 1, t_us = T0 + t,
sink_send_us = t_us + 1 ms, received_us = t_us + 2 ms (T0 = 2021-01-01T00:00:00Z, fixed, so two
conversions are byte-identical), gyro and accelerometer as float32, mag = 0 with the no-mag
flag (kImuNoMag), as the frame reassembler emits a node without a magnetometer; one record per
segment per instant, instants in time order.

Calibration. For segment s, q_sensor_segment = q_pub ⊗ q_isb_mocapd, where q_isb_mocapd turns
mocapd's segment frame (x forward, y left, z up, identity in the T-pose) into the ISB frame of the
same segment: q_isb_mocapd = conj(q_body_isb(A)) ⊗ q_body_mocapd(A), both frames' orientations in
the anatomical position A (standing, arms hanging, palms forward). The ISB frames there are all
q_body_isb(A) = Rx(+90°) (x anterior, y up, z right in body axes). mocapd's segments there:
pelvis, trunk, head, legs and feet identity; upper arms as in the N-pose, Rx(-90°) left and
Rx(+90°) right; forearms and hands N-pose then supinated by 90° (palms from the thighs to the
front), Rz(+90°) ⊗ Rx(-90°) left, Rz(-90°) ⊗ Rx(+90°) right. The published quaternions are
normalised (they are given to 3 decimals). The file says pose = "n-pose" (the take opens
standing with the arms hanging, where a calibration would have been taken; only the hinge-axis
refinement of `[fusion] axis = "estimate"` reads it) and heading = "align" with facing_heading_rad
the pelvis's forward direction in the heading frame its 6-axis filter starts in (the shortest
rotation from its first 0.5 s of specific force to the vertical, filter/marg.hpp,
attitude_from_accel_mag), so the subject faces +x in the viewer at the start. The mapping of the
forearms agrees with the data: walking with the palms at the thighs, their arm swing turns the
forearm sensors about the ISB x axis (anterior only when supinated), and the opening pose reads
as elbow rotation near 0°, shoulders near (0°, 0°, 0°).

--frames segment (a baseline; also what looks right in the viewer, below): writes every sensor's gyroscope and
accelerometer turned into its segment's frame (v_segment = conj(q_sensor_segment) ⊗ v ⊗
q_sensor_segment) with identity mountings. Without a magnetometer a 6-axis filter starts at the
heading of the shortest tilt to the vertical of its own frame, so sensors mounted every which way
start with unrelated headings, and per-segment filters ([fusion] heading = "magnetometer") show
those differences as joint angles (knee rotation near -110° from the first sample here). Segment
frames all stand upright in the opening pose (the arms' hang turned about x only), so their
filters start with nearly one heading: what the recording's published per-segment heading
offsets (left out of the data) did for a 6-axis filter. What is left is the drift. With
[fusion] heading = "joints" the knees, elbows, wrists and ankles take their relative headings from
the joints either way, but the ball joints (spine, neck, shoulders, hips) keep the headings their
filters started with: as recorded, the thighs stand turned ~100° about their length against the
pelvis for the whole take (hip rotation -100°), so play the segment-frame conversion to look at
the motion.

--self-test: converts a synthetic subject standing still in the anatomical position with
sensors mounted at random and checks where the mountings put every segment and what the raw
file holds (self_test()); exit status 1 on a failed check.

recording_pb2: from --pb2-dir or MOCAPD_CLIENT_PB2_DIR if either holds mocap/v1/recording_pb2.py,
else generated by protoc (Debian protobuf-compiler) from proto/mocap/v1/recording.proto into a
temporary directory. Python 3 with Debian's python3-protobuf (run with /usr/bin/python3).
Exit status 1 on a missing or malformed input.
"""

import argparse
import atexit
import csv
import gzip
import importlib
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Default body order (server/skeleton/body_model.hpp): (mocapd segment, recording's segment).
BODY = (
    ("pelvis", "hip"),
    ("trunk", None),  # --trunk
    ("head", "head"),
    ("left_upper_arm", "upper_arm_left"),
    ("left_forearm", "forearm_left"),
    ("left_hand", "hand_left"),
    ("right_upper_arm", "upper_arm_right"),
    ("right_forearm", "forearm_right"),
    ("right_hand", "hand_right"),
    ("left_thigh", "upper_leg_left"),
    ("left_calf", "lower_leg_left"),
    ("left_foot", "foot_left"),
    ("right_thigh", "upper_leg_right"),
    ("right_calf", "lower_leg_right"),
    ("right_foot", "foot_right"),
)
RECORDING_SEGMENTS = ("hip", "lower_back", "upper_back", "head", "upper_arm_left", "forearm_left", "hand_left",
                      "upper_arm_right", "forearm_right", "hand_right", "upper_leg_left", "lower_leg_left",
                      "foot_left", "upper_leg_right", "lower_leg_right", "foot_right")
COLUMNS = ["t", "gx", "gy", "gz", "ax", "ay", "az", "mx", "my", "mz"]
T0_US = 1_609_459_200_000_000  # 2021-01-01T00:00:00Z
IMU_NO_MAG = 1  # kImuNoMag, server/core/imu_sample.hpp
FACING_AVERAGE_S = 0.5


# --------------------------------------------------------------------------------------
# Quaternions (w, x, y, z), Hamilton product, as docs/design.md, "Quaternions and frames"
# --------------------------------------------------------------------------------------

def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def qconj(q):
    return (q[0], -q[1], -q[2], -q[3])


def qnorm(q):
    n = math.sqrt(sum(c * c for c in q))
    return tuple(c / n for c in q)


def canonical(q):
    return q if q[0] >= 0 else tuple(-c for c in q)


def axis_angle(axis, deg):
    h = math.radians(deg) / 2
    return (math.cos(h), axis[0] * math.sin(h), axis[1] * math.sin(h), axis[2] * math.sin(h))


def rotate(q, v):
    return qmul(qmul(q, (0.0, *v)), qconj(q))[1:]


def rx(deg):
    return axis_angle((1, 0, 0), deg)


def rz(deg):
    return axis_angle((0, 0, 1), deg)


IDENTITY = (1.0, 0.0, 0.0, 0.0)


def mocapd_in_anatomical(segment):
    """q_body_segment of mocapd's segment frame in the anatomical position (module comment)."""
    if segment == "left_upper_arm":
        return rx(-90)
    if segment == "right_upper_arm":
        return rx(90)
    if segment in ("left_forearm", "left_hand"):
        return qmul(rz(90), rx(-90))
    if segment in ("right_forearm", "right_hand"):
        return qmul(rz(-90), rx(90))
    return IDENTITY


def q_isb_mocapd(segment):
    return qmul(qconj(rx(90)), mocapd_in_anatomical(segment))


def tilt_to_vertical(up):
    """The shortest rotation taking the unit vector `up` (sensor frame) to earth z: q_earth_sensor
    with zero heading (filter/marg.cpp, attitude_from_accel_mag without magnetometer)."""
    x, y, z = up
    # axis up × z = (y, -x, 0), angle acos(z)
    if z < -1 + 1e-12:
        return (0.0, 1.0, 0.0, 0.0)
    w = 1.0 + z
    return qnorm((w, y, -x, 0.0))


# --------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------

def fail(msg):
    raise SystemExit(f"body_real_convert: {msg}")


def csv_dir(data):
    sub = os.path.join(data, "full_body_16")
    return sub if os.path.isdir(sub) else data


def find_readme(data):
    for d in (data, os.path.dirname(os.path.abspath(data))):
        p = os.path.join(d, "README.md")
        if os.path.isfile(p):
            return p
    fail(f"no README.md with the published sensor-to-segment orientations in {data} or its parent")


def published_orientations(readme):
    """{segment: (w, x, y, z)} from the README's table rows `| name | w, x, y, z |` (two per row)."""
    out = {}
    names = "|".join(RECORDING_SEGMENTS)
    pattern = re.compile(r"\|\s*(" + names + r")\s*\|\s*([-0-9.eE]+)\s*,\s*([-0-9.eE]+)\s*,\s*([-0-9.eE]+)\s*,"
                         r"\s*([-0-9.eE]+)\s*(?=\|)")
    with open(readme, encoding="utf-8") as f:
        for line in f:
            for m in pattern.finditer(line):
                if m.group(1) in out:
                    fail(f"{readme}: {m.group(1)} listed twice")
                q = tuple(float(m.group(k)) for k in range(2, 6))
                if abs(math.sqrt(sum(c * c for c in q)) - 1.0) > 0.01:
                    fail(f"{readme}: {m.group(1)}'s quaternion {q} is not a unit quaternion")
                out[m.group(1)] = qnorm(q)
    missing = [s for s in RECORDING_SEGMENTS if s not in out]
    if missing:
        fail(f"{readme}: no published orientation for {', '.join(missing)}")
    return out


def read_segment(directory, name):
    """[(t_us, gyro (3), accel (3))] of one segment's CSV (.csv.gz or .csv)."""
    for ext, opener in ((".csv.gz", gzip.open), (".csv", open)):
        path = os.path.join(directory, name + ext)
        if os.path.isfile(path):
            break
    else:
        fail(f"no {name}.csv.gz or {name}.csv in {directory}")
    rows = []
    with opener(path, "rt", newline="") as f:
        reader = csv.reader(f)
        header = [h.strip() for h in next(reader)]
        if header[:10] != COLUMNS:
            fail(f"{path}: header {header} is not {','.join(COLUMNS)}")
        for line_no, r in enumerate(reader, start=2):
            try:
                v = [float(x) for x in r[:7]]
            except ValueError:
                fail(f"{path}:{line_no}: not a number")
            if len(r) < 10 or not all(math.isfinite(x) for x in v):
                fail(f"{path}:{line_no}: expected 10 columns with finite t, gyro and accelerometer")
            t_us = round(v[0] * 1e6)
            if rows and t_us <= rows[-1][0]:
                fail(f"{path}:{line_no}: time does not increase")
            rows.append((t_us, v[1:4], v[4:7]))
    if not rows:
        fail(f"{path}: no samples")
    return rows


def load_pb2(pb2_dir):
    """The generated recording_pb2 module (see the module comment)."""
    if "mocap.v1.recording_pb2" in sys.modules:
        return sys.modules["mocap.v1.recording_pb2"]
    try:
        importlib.import_module("google.protobuf")
    except ImportError:
        fail(f"{sys.executable} has no protobuf module: run with /usr/bin/python3 (Debian python3-protobuf)")
    for d in (pb2_dir, os.environ.get("MOCAPD_CLIENT_PB2_DIR")):
        if d and os.path.isfile(os.path.join(d, "mocap", "v1", "recording_pb2.py")):
            sys.path.insert(0, d)
            return importlib.import_module("mocap.v1.recording_pb2")
    protoc = shutil.which("protoc")
    if protoc is None:
        fail("no recording_pb2 (--pb2-dir) and no protoc to generate it (Debian: protobuf-compiler)")
    out = tempfile.mkdtemp(prefix="body_real_pb2_")
    atexit.register(shutil.rmtree, out, True)
    r = subprocess.run([protoc, f"--python_out={out}", f"-I{os.path.join(REPO, 'proto')}",
                        os.path.join(REPO, "proto", "mocap", "v1", "recording.proto")], capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"protoc failed: {r.stderr.strip()}")
    sys.path.insert(0, out)
    return importlib.import_module("mocap.v1.recording_pb2")


# --------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------

def varint(n):
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def write_raw(path, pb2, subject, streams):
    """streams: [(node_id, rows)] with rows sharing their instants. Returns the sample count."""
    n = len(streams[0][1])
    for node, rows in streams:
        if len(rows) != n or any(rows[i][0] != streams[0][1][i][0] for i in range(n)):
            fail(f"node {node}'s samples are not at the same instants as node {streams[0][0]}'s")
    count = 0
    with open(path, "wb") as f:
        f.write(b"MOCAPRAW")
        rec = pb2.RawRecord()
        rec.header.format_version = 1
        rec.header.created_us = T0_US
        rec.header.producer = "body_real_convert.py"
        rec.header.file_index = 0
        data = rec.SerializeToString()
        f.write(varint(len(data)) + data)
        for i in range(n):
            for node, rows in streams:
                t_us, gyro, accel = rows[i]
                rec = pb2.RawRecord()
                s = rec.sample
                s.subject_id = subject
                s.node_id = node
                s.sync = i + 1
                s.t_us = T0_US + t_us
                s.imu_flags = IMU_NO_MAG
                s.gyro_rad_s.extend(gyro)
                s.accel_m_s2.extend(accel)
                s.mag_ut.extend((0.0, 0.0, 0.0))
                s.sink_send_us = T0_US + t_us + 1000
                s.received_us = T0_US + t_us + 2000
                data = rec.SerializeToString()
                f.write(varint(len(data)) + data)
                count += 1
    return count


def fmt(v):
    return repr(float(v))  # shortest text that reads back as the same double


def fmt_quat(q):
    return "[" + ", ".join(fmt(c) for c in q) + "]"


def calibration_text(mountings, facing_rad, frames):
    lines = [
        "# mocapd sensor-to-segment calibration: q_earth_segment = q_earth_sensor * q_sensor_segment",
        "# written by tests/bench/body_real_convert.py from the recording's published sensor-to-segment",
        "# orientations (ISB frames)" + (" (--frames segment: the samples are in the segment frames)"
                                          if frames == "segment" else ""),
        'format = "mocapd-calibration"',
        "version = 1",
        'pose = "n-pose"',
        'heading = "align"',
        f"facing_heading_rad = {fmt(facing_rad)}",
        f"q_world_earth = {fmt_quat(canonical(rz(-math.degrees(facing_rad))))}",
        "",
        "[q_sensor_segment]",
    ]
    lines += [f"{seg} = {fmt_quat(q)}" for seg, q in mountings]
    return "\n".join(lines) + "\n"


def play_config(calibration_dir, heading="joints"):
    return f"""# mocapd --config play.toml --play body_real.mocapraw --loop (written by body_real_convert.py)
[fusion]
heading = "{heading}"
[skeleton]
calibration_dir = "{calibration_dir}"
auto_calibrate = "off"
"""


def to_segment_frame(rows, q_sensor_segment):
    """rows with gyro and accelerometer turned from the sensor's frame into the segment's."""
    q = qconj(q_sensor_segment)
    return [(t, rotate(q, g), rotate(q, a)) for t, g, a in rows]


def convert(data, out, trunk="upper_back", subject=1, pb2_dir=None, quiet=False, frames="sensor"):
    """Converts DATA into OUT (module comment); returns a dict of what was written."""
    if frames not in ("sensor", "segment"):
        fail(f"--frames must be sensor or segment, not {frames}")
    if trunk not in ("upper_back", "lower_back"):
        fail(f"--trunk must be upper_back or lower_back, not {trunk}")
    directory = csv_dir(data)
    readme = find_readme(data)
    published = published_orientations(readme)
    pb2 = load_pb2(pb2_dir)
    body = [(seg, trunk if src is None else src) for seg, src in BODY]
    streams, mountings = [], []
    for node, (seg, src) in enumerate(body, start=1):
        rows = read_segment(directory, src)
        mounting = canonical(qnorm(qmul(published[src], q_isb_mocapd(seg))))
        if frames == "segment":
            rows, mounting = to_segment_frame(rows, mounting), IDENTITY
        streams.append((node, rows))
        mountings.append((seg, mounting))
    # Facing: the pelvis's forward axis (mocapd x) in its filter's starting heading frame.
    pelvis_rows = streams[0][1]
    first = [r for r in pelvis_rows if r[0] - pelvis_rows[0][0] < FACING_AVERAGE_S * 1e6]
    acc = [sum(r[2][k] for r in first) for k in range(3)]
    up = qnorm((0.0, *acc))[1:]
    forward = rotate(tilt_to_vertical(up), rotate(mountings[0][1], (1.0, 0.0, 0.0)))
    facing = math.atan2(forward[1], forward[0])

    os.makedirs(out, exist_ok=True)
    raw = os.path.join(out, "body_real.mocapraw")
    samples = write_raw(raw, pb2, subject, streams)
    cal_dir = os.path.join(os.path.abspath(out), "calibration")
    os.makedirs(cal_dir, exist_ok=True)
    cal = os.path.join(cal_dir, f"calibration-subject-{subject}.toml")
    with open(cal, "w") as f:
        f.write(calibration_text(mountings, facing, frames))
    play = os.path.join(out, "play.toml")
    with open(play, "w") as f:
        f.write(play_config(cal_dir))
    seconds = (pelvis_rows[-1][0] - pelvis_rows[0][0]) / 1e6
    if not quiet:
        dropped = "lower_back" if trunk == "upper_back" else "upper_back"
        print(f"body_real_convert: {samples} samples ({len(streams)} nodes, {len(pelvis_rows)} instants, "
              f"{seconds:.2f} s; trunk = {trunk}, {dropped} dropped; {frames} frames)")
        print(f"  {raw}\n  {cal}\n  {play}")
        print(f"  play:   mocapd --config {play} --play {raw} --loop")
        print(f"  replay: mocapd --config CFG --replay {raw} --calibration-dir {cal_dir} --angles-out A.csv")
    return {"raw": raw, "calibration_dir": cal_dir, "calibration": cal, "play_config": play, "samples": samples,
            "instants": len(pelvis_rows), "seconds": seconds, "facing_heading_rad": facing}


# --------------------------------------------------------------------------------------
# Self-test: a synthetic subject standing in the anatomical position
# --------------------------------------------------------------------------------------

def read_varint(data, pos):
    """(value, position after it) of the base-128 varint at data[pos]."""
    n, shift = 0, 0
    while True:
        b = data[pos]
        pos += 1
        n |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return n, pos


def read_raw(path, pb2):
    """[RawSample] of a raw recording (after the magic and the header)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"MOCAPRAW":
        fail(f"{path}: no MOCAPRAW magic")
    pos, out, first = 8, [], True
    while pos < len(data):
        n, pos = read_varint(data, pos)
        rec = pb2.RawRecord()
        rec.ParseFromString(data[pos:pos + n])
        pos += n
        if first != rec.HasField("header"):
            fail(f"{path}: the header is not (only) the first record")
        if not first:
            out.append(rec.sample)
        first = False
    return out


def self_test(pb2_dir=None):
    """Writes a synthetic recording (every sensor mounted at random, the subject still in the
    anatomical position facing 30° from east), converts it and checks (1) the mountings put
    every mocapd segment where mocapd's conventions say it is in that pose: trunk, head, legs
    and feet x forward and z up; upper arms x forward and their distal axis (+y left, -y right)
    down; forearms and hands the distal axis down and the palm (-z, down in the T-pose)
    forward; (2) the raw file: one record per segment per instant, node ids 1..15 in body
    order carrying their segment's samples, the no-magnetometer flag, SYNCs and times.
    Returns the number of failed checks."""
    import random
    rnd = random.Random(7)
    psi = 30.0
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)

    def random_quat():
        return qnorm(tuple(rnd.gauss(0, 1) for _ in range(4)))

    def near(u, v, tol=1e-9):
        return max(abs(a - b) for a, b in zip(u, v)) < tol

    # Written out again here, not taken from BODY, so that a wrong table fails: the default
    # body's segments in node order (body_model.hpp) and the recording's segment for each.
    expected = (("pelvis", "hip"), ("trunk", "upper_back"), ("head", "head"), ("left_upper_arm", "upper_arm_left"),
                ("left_forearm", "forearm_left"), ("left_hand", "hand_left"), ("right_upper_arm", "upper_arm_right"),
                ("right_forearm", "forearm_right"), ("right_hand", "hand_right"), ("left_thigh", "upper_leg_left"),
                ("left_calf", "lower_leg_left"), ("left_foot", "foot_left"), ("right_thigh", "upper_leg_right"),
                ("right_calf", "lower_leg_right"), ("right_foot", "foot_right"))
    work = tempfile.mkdtemp(prefix="body_real_selftest_")
    try:
        data = os.path.join(work, "data")
        os.makedirs(os.path.join(data, "full_body_16"))
        q_earth_isb = qmul(rz(psi), rx(90))  # ISB frames in the anatomical position, facing psi
        published = {s: random_quat() for s in RECORDING_SEGMENTS}
        table = ["| segment | q_segment_to_sensor | | segment | q_segment_to_sensor |", "|---|---|---|---|---|"]
        names = list(RECORDING_SEGMENTS)
        for i in range(0, len(names), 2):
            cells = [f"| {n} | {', '.join(f'{c:.17g}' for c in published[n])} " for n in names[i:i + 2]]
            table.append("".join(cells) + "|")
        with open(os.path.join(data, "README.md"), "w") as f:
            f.write("synthetic\n\n" + "\n".join(table) + "\n")
        for k, name in enumerate(RECORDING_SEGMENTS):
            q_earth_sensor = qmul(q_earth_isb, qconj(published[name]))
            g = rotate(qconj(q_earth_sensor), (0.0, 0.0, 9.81))
            with gzip.open(os.path.join(data, "full_body_16", name + ".csv.gz"), "wt") as f:
                f.write(",".join(COLUMNS) + "\n")
                for i in range(100):  # the gyro's x marks the segment: 0.001 * (k + 1)
                    f.write(f"{i / 100:.2f},{0.001 * (k + 1)},0,0,{g[0]!r},{g[1]!r},{g[2]!r},nan,nan,nan\n")
        conv = convert(data, os.path.join(work, "out"), pb2_dir=pb2_dir, quiet=True)
        cal = {}
        with open(conv["calibration"]) as f:
            for line in f:
                m = re.match(r"(\w+) = \[([^]]*)\]", line)
                if m and m.group(1) != "q_world_earth":
                    cal[m.group(1)] = tuple(float(c) for c in m.group(2).split(","))
        fwd, up = (math.cos(math.radians(psi)), math.sin(math.radians(psi)), 0.0), (0.0, 0.0, 1.0)
        down = (0.0, 0.0, -1.0)
        check(list(cal) == [seg for seg, _ in expected], f"calibration segments {list(cal)}")
        for seg, src in expected:
            q = qmul(qmul(q_earth_isb, qconj(published[src])), cal[seg])  # q_earth_segment, mocapd frame
            distal = (0, 1, 0) if seg.startswith("left") else (0, -1, 0)  # body_model.hpp: end_m
            ax = {a: rotate(q, v) for a, v in (("x", (1, 0, 0)), ("distal", distal), ("-z", (0, 0, -1)))}
            ax["z"] = tuple(-c for c in ax["-z"])
            if "arm" in seg and "fore" not in seg:
                want = {"x": fwd, "distal": down}
            elif "forearm" in seg or "hand" in seg:
                want = {"distal": down, "-z": fwd}
            else:
                want = {"x": fwd, "z": up}
            for a, v in want.items():
                check(near(ax[a], v), f"{seg}: its {a} axis is {tuple(round(c, 3) for c in ax[a])}, not {v}")
        pb2 = load_pb2(pb2_dir)
        samples = read_raw(conv["raw"], pb2)
        n = len(expected)
        check(len(samples) == 100 * n, f"{len(samples)} samples, not {100 * n}")
        for i, s in enumerate(samples):
            node = i % n + 1
            marker = 0.001 * (RECORDING_SEGMENTS.index(expected[node - 1][1]) + 1)
            ok = (s.subject_id == 1 and s.node_id == node and s.sync == i // n + 1 and s.imu_flags == IMU_NO_MAG
                  and s.t_us == T0_US + (i // n) * 10_000 and s.received_us == s.t_us + 2000
                  and abs(s.gyro_rad_s[0] - marker) < 1e-7 and list(s.mag_ut) == [0.0, 0.0, 0.0])
            check(ok, f"sample {i}: {s}")
            if not ok:
                break
    finally:
        shutil.rmtree(work, ignore_errors=True)
    for f in failures:
        print(f"body_real_convert: self-test: {f}", file=sys.stderr)
    print(f"body_real_convert: self-test {'failed' if failures else 'passed'} ({len(failures)} failed checks)")
    return len(failures)


def main():
    if sys.argv[1:] == ["--self-test"]:
        sys.exit(1 if self_test() else 0)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="the recording's directory (README.md and full_body_16/)")
    ap.add_argument("--out", required=True, help="output directory (created)")
    ap.add_argument("--frames", default="sensor", choices=("sensor", "segment"),
                    help="sensor: the samples as recorded (default); segment: turned into the segment frames")
    ap.add_argument("--trunk", default="upper_back", choices=("upper_back", "lower_back"),
                    help="the sensor that becomes the trunk (default upper_back; the other is dropped)")
    ap.add_argument("--subject", type=int, default=1, help="subject id (default 1: sink 1, subject_id_base 0)")
    ap.add_argument("--pb2-dir", help="a directory holding mocap/v1/recording_pb2.py (default: generate it)")
    a = ap.parse_args()
    if not 1 <= a.subject < 2**32:
        fail("--subject out of range")
    convert(a.data, a.out, a.trunk, a.subject, a.pb2_dir, frames=a.frames)


if __name__ == "__main__":
    main()
