#!/usr/bin/python3
"""Error and disturbance flags over time: runs `mocap-filter --trace` on one recording (the
mocap-filter CSV format with a reference, gzip ok) and plots the total and heading error next
to the filter's flags and field-offset estimate. Writes a PNG (matplotlib).

    /usr/bin/python3 tests/bench/accuracy_trace_plot.py --in REC.csv[.gz] --out PLOT.png
                     [--build build] [--filter mocap] [--title TEXT]

Exit status 1 if the tool fails or matplotlib is missing.
"""

import argparse
import csv
import gzip
import math
import os
import shutil
import subprocess
import sys
import tempfile


def read_csv(path):
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt", newline="") as f:
        r = csv.reader(f)
        header = next(r)
        cols = {k: [] for k in header}
        for row in r:
            for k, v in zip(header, row):
                cols[k].append(float(v))
    return cols


def qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2)


def errors_deg(est, ref):
    """BROAD total and heading error of q_est ⊗ conj(q_ref) (docs/design.md, "Error metrics")."""
    w, x, y, z = qmul(est, (ref[0], -ref[1], -ref[2], -ref[3]))
    total = math.degrees(2.0 * math.acos(min(1.0, abs(w))))
    heading = math.degrees(2.0 * math.atan(abs(z / w))) if w != 0.0 else 180.0
    return total, heading


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--in", dest="inp", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--build", default=os.environ.get("MOCAP_BUILD_DIR", "build"))
    ap.add_argument("--filter", default="mocap")
    ap.add_argument("--title", default="")
    args = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("accuracy_trace_plot: matplotlib is missing (run with /usr/bin/python3)", file=sys.stderr)
        return 1
    tool = os.path.join(args.build, "clients", "filter_tool", "mocap-filter")
    with tempfile.TemporaryDirectory(prefix="mocap_trace_") as tmp:
        rec = args.inp
        if rec.endswith(".gz"):
            rec = os.path.join(tmp, "rec.csv")
            with gzip.open(args.inp, "rb") as src, open(rec, "wb") as dst:
                shutil.copyfileobj(src, dst)
        est_path, trace_path = os.path.join(tmp, "est.csv"), os.path.join(tmp, "trace.csv")
        p = subprocess.run([tool, "--filter", args.filter, "--in", rec, "--out", est_path, "--trace", trace_path],
                           capture_output=True, text=True)
        if p.returncode != 0:
            print("accuracy_trace_plot: mocap-filter failed: %s" % p.stderr.strip(), file=sys.stderr)
            return 1
        data, est, tr = read_csv(rec), read_csv(est_path), read_csv(trace_path)

    t = tr["t"]
    total, heading = [], []
    for i in range(len(t)):
        ref = (data["qw"][i], data["qx"][i], data["qy"][i], data["qz"][i])
        if data.get("movement", [1.0] * len(t))[i] != 1.0 or any(math.isnan(c) for c in ref):
            total.append(float("nan"))
            heading.append(float("nan"))
            continue
        e = errors_deg((est["qw"][i], est["qx"][i], est["qy"][i], est["qz"][i]), ref)
        total.append(e[0])
        heading.append(e[1])
    offset = [math.sqrt(a * a + b * b + c * c) for a, b, c in zip(tr["mag_offset_x"], tr["mag_offset_y"],
                                                                   tr["mag_offset_z"])]

    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, sharex=True, figsize=(10, 7),
                                        gridspec_kw={"height_ratios": [3, 2, 2]})
    ax1.plot(t, total, lw=0.6, label="total error")
    ax1.plot(t, heading, lw=0.6, label="heading error")
    ax1.set_ylabel("error, °")
    ax1.legend(loc="upper right")
    ax1.set_title(args.title or "%s on %s" % (args.filter, os.path.basename(args.inp)))
    ax1.grid(alpha=0.3)
    flags = [("mag_rejected", "field rejected"), ("mag_field_disturbed", "norm / dip off"),
             ("mag_heading_disturbed", "heading disagrees"), ("rest", "rest")]
    for k, (key, label) in enumerate(flags):
        ax2.fill_between(t, [k + 0.8 * v for v in tr[key]], k, step="post", alpha=0.6, label=label)
    ax2.set_yticks([k + 0.4 for k in range(len(flags))])
    ax2.set_yticklabels([label for _, label in flags])
    ax2.grid(alpha=0.3, axis="x")
    ax3.plot(t, offset, lw=0.8, color="C3", label="|field offset estimate|, µT")
    ax3.plot(t, [5.0 * w for w in tr["mag_offset_weight"]], lw=0.8, color="C4",
             label="share subtracted (×5)")
    ax3b = ax3.twinx()
    ax3b.plot(t, tr["bias_z"], lw=0.8, color="C2", label="gyro bias z, °/s")
    ax3b.set_ylabel("°/s")
    ax3.set_ylabel("µT")
    ax3.set_xlabel("t, s")
    h1, l1 = ax3.get_legend_handles_labels()
    h2, l2 = ax3b.get_legend_handles_labels()
    ax3.legend(h1 + h2, l1 + l2, loc="upper right", fontsize="small")
    ax3.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out, dpi=90)
    print("wrote %s" % args.out, file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
