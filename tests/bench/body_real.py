#!/usr/bin/env python3
"""body_real.py — knees and elbows of a real 16-IMU recording without magnetometer through
`mocapd --replay`, per-segment headings against headings held by the joints (docs/fusion.md).

    /usr/bin/python3 tests/bench/body_real.py DATA [--bin build] [--mocapd PATH] [--window-s 20]
        [--joints left_knee,right_knee,left_elbow,right_elbow] [--json OUT.json] [--keep DIR]

The tables of docs/fusion.md ("Real recording"): `/usr/bin/python3 tests/bench/body_real.py DATA
--bin build` (add `--joints left_ankle,right_ankle,left_hip,right_hip` for the other joints).

DATA: the recording's directory as tests/bench/body_real_convert.py reads it (the full-body
example of the qmt toolbox, github.com/dlaidig/qmt, examples/full_body_example_data.mat, as one
CSV per segment; SPDX-FileCopyrightText: 2021 Bo Yang; SPDX-License-Identifier: MIT; 100 s at
100 Hz, no magnetometer, no ground truth). Nothing of it is in this repository.

What it runs. body_real_convert.py turns DATA into a raw recording twice, into a temporary
directory (or --keep DIR): as recorded (sensor frames, the published mountings in the
calibration) and with every sensor turned into its segment's frame (identity mountings;
body_real_convert.py, --frames segment). Then, each with its own copy of the calibration
directory (axis = "estimate" saves refined mountings there), a config with auto_calibrate =
"off" and the shipped defaults otherwise (filter "mocap"),

    mocapd --config CFG --replay body_real.mocapraw --calibration-dir CAL --angles-out A.csv

for these configurations:
  magnetometer, as recorded    heading = "magnetometer": every segment its own 6-axis filter's
                               heading. Without a magnetometer each filter starts at the heading
                               of its sensor's shortest tilt, so the relative headings are
                               arbitrary from the first sample.
  magnetometer, aligned        the same on the segment-frame conversion: the filters start with
                               nearly one heading (what the recording's per-segment heading
                               offsets did), so what grows is the per-segment filters' drift.
  joints, axis model           heading = "joints", axis = "model", as recorded.
  joints, axis estimate        heading = "joints", axis = "estimate", as recorded.
  joints, axis model, aligned  heading = "joints" on the segment-frame conversion: the chain stage
                               should not care how the sensors started (same knees as recorded).

What it reports, per configuration and joint (the joint-angle CSV, docs/outputs.md; angles of
skeleton/joint_angles.hpp, degrees): the flexion range (min..max: the joint moved), and of the
two non-flexion angles, abduction and rotation, the RMS and the largest magnitude about zero
(the anatomical neutral) over the whole take, the first and the last --window-s seconds (drift);
then a second table, their means over each consecutive window (the offset drift builds up, apart
from the oscillation within each step).
The knee is a hinge in the chain stage (body_chain.hpp): its abduction and rotation should stay
within a few degrees. The elbow is 2-DoF: its abduction is held, its rotation is pronation, a
real degree of freedom, reported for its drift only. The mountings were found by hand and the
thigh sensors wobble on soft tissue (their gyroscopes read several rad/s about the thigh's long
axis at heel strikes), so "within a few degrees" includes that: there is no ground truth.

Prints one markdown table per window layout to stdout and the commands it ran to stderr; --json
keeps every number. Python 3 with Debian's python3-protobuf and python3-numpy (run it with
/usr/bin/python3). About 10 s. Exit status 1 when a tool fails.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

try:
    import numpy as np
except ImportError:
    raise SystemExit(f"body_real: {sys.executable} has no numpy: run with /usr/bin/python3 (Debian python3-numpy)")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import body_real_convert  # noqa: E402
from load_run import find_binary  # noqa: E402

REPO = os.path.dirname(os.path.dirname(HERE))
DEFAULT_JOINTS = "left_knee,right_knee,left_elbow,right_elbow"

# (label, conversion, heading, axis)
CONFIGS = (
    ("magnetometer, as recorded", "sensor", "magnetometer", "model"),
    ("magnetometer, aligned", "segment", "magnetometer", "model"),
    ("joints, axis model", "sensor", "joints", "model"),
    ("joints, axis estimate", "sensor", "joints", "estimate"),
    ("joints, axis model, aligned", "segment", "joints", "model"),
)


def replay_config(heading, axis):
    return f"""[log]
level = "info"
stats_interval_s = 0
[fusion]
heading = "{heading}"
axis = "{axis}"
[skeleton]
auto_calibrate = "off"
[http]
enabled = false
[outputs]
bvh_live = false
"""


def replay(mocapd, conv, heading, axis, work):
    """One replay; returns (angles CSV, mocapd's summary line, log lines of interest)."""
    os.makedirs(work, exist_ok=True)
    cal = os.path.join(work, "calibration")
    shutil.copytree(conv["calibration_dir"], cal)
    cfg = os.path.join(work, "replay.toml")
    with open(cfg, "w") as f:
        f.write(replay_config(heading, axis))
    out = os.path.join(work, "angles.csv")
    cmd = [mocapd, "--config", cfg, "--replay", conv["raw"], "--calibration-dir", cal, "--angles-out", out]
    print("+ " + " ".join(cmd), file=sys.stderr)
    r = subprocess.run(cmd, capture_output=True, text=True)
    text = r.stdout + r.stderr
    if r.returncode != 0:
        raise SystemExit(f"body_real: {' '.join(cmd)} exited {r.returncode}:\n{text[-3000:]}")
    summary = next((l.strip() for l in text.splitlines() if l.startswith("replayed")), "")
    notes = [l.split("] ", 2)[-1] for l in text.splitlines() if "refined" in l or "calibration loaded" in l]
    return out, summary, notes


def read_angles(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
    if header[:3] != ["subject", "sync", "t_s"]:
        raise SystemExit(f"body_real: {path} is not a joint-angle CSV")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {h[:-4] if h.endswith("_deg") else h: rows[:, i] for i, h in enumerate(header)}


def stats(x):
    return {"rms_deg": float(np.sqrt(np.mean(x * x))), "max_abs_deg": float(np.max(np.abs(x)))} if x.size else None


def evaluate(path, joints, window_s):
    a = read_angles(path)
    t = a["t_s"] - a["t_s"][0]
    windows = {"all": np.ones_like(t, dtype=bool), "first": t < window_s, "last": t >= t[-1] - window_s}
    out = {"frames": int(t.size), "duration_s": float(t[-1])}
    for j in joints:
        if f"{j}.flexion" not in a:
            raise SystemExit(f"body_real: no joint {j} in {path}")
        flex = a[f"{j}.flexion"]
        e = {"flexion_min_deg": float(flex.min()), "flexion_max_deg": float(flex.max())}
        for angle in ("abduction", "rotation"):
            x = a[f"{j}.{angle}"]
            e[angle] = {w: stats(x[m]) for w, m in windows.items()}
            edges = np.arange(0.0, t[-1] + 1e-9, window_s)
            e[angle]["window_means_deg"] = [float(np.mean(x[(t >= lo) & (t < lo + window_s)])) for lo in edges
                                            if np.any((t >= lo) & (t < lo + window_s))]
        out[j] = e
    return out


def f1(v):
    return f"{v:.1f}"


def table(results, joints, window_s):
    w = f"{window_s:g} s"
    lines = [
        f"| configuration | joint | flexion range | abduction RMS / max: all | first {w} | last {w} "
        f"| rotation RMS / max: all | first {w} | last {w} |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, r in results:
        for j in joints:
            e = r[j]
            cells = [label, j.replace("_", " "), f"{e['flexion_min_deg']:.0f}..{e['flexion_max_deg']:.0f}°"]
            for angle in ("abduction", "rotation"):
                for win in ("all", "first", "last"):
                    s = e[angle][win]
                    cells.append(f"{f1(s['rms_deg'])} / {f1(s['max_abs_deg'])}")
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def drift_table(results, joints, window_s):
    """Mean abduction / rotation per consecutive window: the offset that drift builds up, without
    the oscillation of each step that the RMS also holds."""
    n = max(len(r[j]["rotation"]["window_means_deg"]) for _, r in results for j in joints)
    heads = [f"{k * window_s:g}-{(k + 1) * window_s:g} s" for k in range(n)]
    lines = ["| configuration | joint | " + " | ".join(heads) + " |", "|---|---|" + "---|" * n]
    for label, r in results:
        for j in joints:
            ab, ro = r[j]["abduction"]["window_means_deg"], r[j]["rotation"]["window_means_deg"]
            cells = [f"{f1(x)} / {f1(y)}" for x, y in zip(ab, ro)]
            lines.append(f"| {label} | {j.replace('_', ' ')} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", help="the recording's directory (README.md and full_body_16/)")
    ap.add_argument("--bin", help="a build tree holding mocapd (default: build/ of this checkout)")
    ap.add_argument("--mocapd", help="the mocapd binary (overrides --bin)")
    ap.add_argument("--window-s", type=float, default=20.0, help="first and last window, s (default 20)")
    ap.add_argument("--joints", default=DEFAULT_JOINTS, help=f"joints to report (default {DEFAULT_JOINTS})")
    ap.add_argument("--json", help="write every number here")
    ap.add_argument("--keep", help="work in this directory and keep it (default: a temporary one, removed)")
    a = ap.parse_args()
    mocapd = a.mocapd or find_binary(a.bin or os.path.join(REPO, "build"), "mocapd")
    joints = [j.strip() for j in a.joints.split(",") if j.strip()]
    work = a.keep or tempfile.mkdtemp(prefix="body_real_")
    try:
        conv = {}
        for frames in ("sensor", "segment"):
            conv[frames] = body_real_convert.convert(a.data, os.path.join(work, f"conv-{frames}"), frames=frames,
                                                     quiet=True)
        results, record = [], {"mocapd": mocapd, "window_s": a.window_s, "configurations": []}
        for i, (label, frames, heading, axis) in enumerate(CONFIGS):
            csv_path, summary, notes = replay(mocapd, conv[frames], heading, axis, os.path.join(work, f"run{i}"))
            r = evaluate(csv_path, joints, a.window_s)
            results.append((label, r))
            record["configurations"].append({"label": label, "frames": frames, "heading": heading, "axis": axis,
                                             "summary": summary, "log": notes, "angles": r})
            refined = sum("refined" in n for n in notes)
            print(f"body_real: {label}: {summary}" + (f"; mountings refined {refined} time(s)"
                                                         if axis == "estimate" else ""), file=sys.stderr)
        print(table(results, joints, a.window_s))
        print(f"\nMean abduction / rotation (°) per {a.window_s:g} s window:\n")
        print(drift_table(results, joints, a.window_s))
        if a.json:
            with open(a.json, "w") as f:
                json.dump(record, f, indent=1)
                f.write("\n")
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
