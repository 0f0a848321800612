#!/usr/bin/env python3
"""Records knee and elbow flexion of one subject from mocapd and plots them into a PNG.

    record_angles.py --connect 127.0.0.1:7001 --duration 10 --out angles.png
    MOCAP_TOKEN=... record_angles.py --calibrate --out angles.png   # T-pose calibrate first

Joint angles are only anatomical once the subject is calibrated (segment flag CALIBRATED);
--calibrate sends the calibrate request (the subject must stand still in the T-pose) and
waits until every segment is calibrated before recording. Exit: 0 ok, 1 no frames or a
refused request, 2 connection problem.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

try:
    import mocapd_client as mc
except ImportError:  # run from the source tree without PYTHONPATH
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import mocapd_client as mc

import numpy as np

JOINTS = ("left_knee", "right_knee", "left_elbow", "right_elbow")


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--connect", default="127.0.0.1:7001", help="mocapd pose port, HOST:PORT")
    p.add_argument("--subject", type=int, default=0, help="subject id (0 = the first one that sends)")
    p.add_argument("--duration", type=float, default=10.0, help="seconds to record")
    p.add_argument("--out", default="angles.png", help="PNG to write")
    p.add_argument("--csv", help="also write the angles (degrees) as CSV")
    p.add_argument("--calibrate", action="store_true", help="T-pose calibrate before recording")
    p.add_argument("--token", default=os.environ.get("MOCAP_TOKEN", ""),
                   help="control token for --calibrate (default: $MOCAP_TOKEN)")
    p.add_argument("--settle-s", type=float, default=1.0, help="seconds of frames before calibrating")
    return p.parse_args(argv)


def first_frame(client: mc.Client, subject: int) -> mc.Frame:
    for f in client.frames(idle_timeout=10.0):
        if subject == 0 or f.subject_id == subject:
            return f
    raise mc.ConnectionClosed(client.goodbye)


def calibrate(client: mc.Client, subject: int, token: str, settle_s: float) -> None:
    start = time.monotonic()
    for _ in client.frames(duration=settle_s):
        pass
    reply = client.control(token, calibrate=subject, pose="T")
    if not reply.ok:
        raise PermissionError(f"calibrate refused: {reply.error}")
    end = time.monotonic() + 15.0
    for f in client.frames(idle_timeout=5.0):
        if f.subject_id == subject and f.all_flagged(mc.SegmentFlags.CALIBRATED):
            print(f"calibrated after {time.monotonic() - start:.1f} s", file=sys.stderr)
            return
        if time.monotonic() > end:
            break
    raise TimeoutError("the subject did not become calibrated within 15 s")


def record(client: mc.Client, subject: int, duration_s: float, columns: list[int]):
    t_us, rows = [], []
    for f in client.frames(duration=duration_s):
        if f.subject_id != subject:
            continue
        t_us.append(f.sample_us)
        rows.append(np.degrees(f.joint_angles_rad[columns]))
    if not rows:
        return np.empty(0), np.empty((0, len(columns)))
    return (np.array(t_us) - t_us[0]) / 1e6, np.array(rows)


def plot(t_s, deg, subject: int, out: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(10, 5.5), constrained_layout=True)
    for ax, (k, joint) in zip(axes, ((0, "knee"), (2, "elbow"))):
        ax.plot(t_s, deg[:, k], label=f"left {joint}", color="tab:blue")
        ax.plot(t_s, deg[:, k + 1], label=f"right {joint}", color="tab:orange")
        ax.set_ylabel(f"{joint} flexion (deg)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    axes[-1].set_xlabel("time (s)")
    rate = (len(t_s) - 1) / t_s[-1] if len(t_s) > 1 and t_s[-1] > 0 else 0.0
    axes[0].set_title(f"mocapd subject {subject}: {len(t_s)} frames, {rate:.0f} Hz")
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        client = mc.Client.from_endpoint(args.connect, timeout=5.0)
        info = client.connect()
    except (OSError, ValueError, mc.ProtocolError) as e:
        print(f"record_angles: cannot connect to {args.connect}: {e}", file=sys.stderr)
        return 2
    with client:
        names = info.skeleton.joint_angle_names
        missing = [j for j in JOINTS if f"{j}.flexion" not in names]
        if missing:
            print(f"record_angles: the skeleton has no {', '.join(missing)}", file=sys.stderr)
            return 1
        columns = [names.index(f"{j}.flexion") for j in JOINTS]
        try:
            client.subscribe(subjects=[args.subject] if args.subject else None,
                             fields=mc.Fields.ORIENTATIONS | mc.Fields.JOINT_ANGLES)
            first = first_frame(client, args.subject)
            subject = first.subject_id
            if args.calibrate:
                calibrate(client, subject, args.token, args.settle_s)
            elif not first.all_flagged(mc.SegmentFlags.CALIBRATED):
                print("record_angles: subject not calibrated; angles are between raw sensor frames "
                      "(use --calibrate)", file=sys.stderr)
            t_s, deg = record(client, subject, args.duration, columns)
        except (TimeoutError, PermissionError) as e:
            print(f"record_angles: {e}", file=sys.stderr)
            return 1
        except (OSError, mc.ProtocolError) as e:
            print(f"record_angles: {e}", file=sys.stderr)
            return 2
    if len(t_s) < 2:
        print("record_angles: no frames recorded", file=sys.stderr)
        return 1
    plot(t_s, deg, subject, args.out)
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_s"] + [f"{j}_flexion_deg" for j in JOINTS])
            for t, row in zip(t_s, deg):
                w.writerow([f"{t:.4f}"] + [f"{v:.3f}" for v in row])
    ranges = ", ".join(f"{j} {deg[:, i].min():.0f}..{deg[:, i].max():.0f}" for i, j in enumerate(JOINTS))
    print(f"{len(t_s)} frames over {t_s[-1]:.2f} s, drops {client.drops_announced}; flexion deg: {ranges}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
