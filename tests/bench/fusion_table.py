#!/usr/bin/env python3
"""fusion_table.py — the chain figures of docs/fusion.md, from the real tools.

Generates the simulator's chain recordings (`mocap-sim csv --scenario chain|pendulum`, seeds
1..N), runs `mocap-filter --chain` over each under every heading choice (per-segment
magnetometer, joints, auto, no magnetometer), causal and offline, with the joint axes given
and learned from the motion, and prints markdown tables of the mean relative-orientation
error of adjacent segments (the issue's metric: mean after 5 s; the hinge joints of the arm,
the one joint of the pendulum), median over the seeds, with the last-30-s mean beside it to
show drift. With --plot PNG it also draws the relative heading error of one arm recording
over time, per-segment against body-aware (matplotlib).

    tests/bench/fusion_table.py --build build [--seeds 3] [--plot docs/fusion_heading.png]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit("fusion_table: %s failed:\n%s" % (" ".join(cmd), r.stderr[-2000:]))
    return r.stdout


def strip_axes(src, dst):
    with open(src) as f, open(dst, "w") as g:
        for line in f:
            if not line.startswith("axis_"):
                g.write(line)


CONFIGS = [
    ("per segment (magnetometer)", ["--heading", "magnetometer"]),
    ("joints", ["--heading", "joints"]),
    ("auto", ["--heading", "auto"]),
    ("no magnetometer", ["--no-mag"]),
    ("auto, offline", ["--heading", "auto", "--offline"]),
    ("no magnetometer, offline", ["--no-mag", "--offline"]),
]


def evaluate(filt, toml, out, args, kind):
    d = json.loads(run([filt, "--chain", toml, "--out-dir", out, "--eval"] + args))
    joints = [j for j in d["joints"] if kind == "pendulum" or j["type"] == "hinge"]
    mean = sum(j["mean_deg"] for j in joints) / len(joints)
    last = sum(j["last30_mean_deg"] for j in joints) / len(joints)
    return mean, last


def table(kind, filt, sim, seeds, work):
    rows = {}
    for seed in range(1, seeds + 1):
        d = os.path.join(work, "%s%d" % (kind, seed))
        os.makedirs(d, exist_ok=True)
        toml = os.path.join(d, "chain.toml")
        run([sim, "csv", "--scenario", kind, "--seed", str(seed), "--out", toml])
        learned = os.path.join(d, "learned.toml")
        strip_axes(toml, learned)
        for axes, path in (("given", toml), ("learned", learned)):
            for name, args in CONFIGS:
                m = evaluate(filt, path, os.path.join(d, "out"), args, kind)
                rows.setdefault((name, axes), []).append(m)
    print("\n| %s: heading | axes | mean (°) | last 30 s (°) | seeds |" % kind)
    print("| --- | --- | ---: | ---: | --- |")
    for (name, axes), ms in rows.items():
        print("| %s | %s | %.2f | %.2f | %s |" % (name, axes, statistics.median(m[0] for m in ms),
                                                  statistics.median(m[1] for m in ms),
                                                  ", ".join("%.1f" % m[0] for m in ms)))


def plot(filt, sim, work, png):
    import numpy as np
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    d = os.path.join(work, "plot")
    os.makedirs(d, exist_ok=True)
    toml = os.path.join(d, "chain.toml")
    run([sim, "csv", "--scenario", "chain", "--seed", "1", "--out", toml])

    def rel_heading(out):
        def q(name):
            return np.loadtxt(os.path.join(out, name + ".csv"), delimiter=",", skiprows=1)
        def ref(name):
            return np.loadtxt(os.path.join(d, name + ".csv"), delimiter=",", skiprows=1)[:, 10:14]
        def mul(a, b):
            w1, x1, y1, z1 = a.T
            w2, x2, y2, z2 = b.T
            return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                             w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], 1)
        conj = np.array([1, -1, -1, -1])
        ep, ec = q("seg2")[:, 1:5], q("seg3")[:, 1:5]
        rp, rc = ref("seg2"), ref("seg3")
        # the child's orientation error times the inverse of the parent's, in the earth frame:
        # a common heading offset of the whole chain (no magnetometer) cancels, and its part
        # about the vertical is the relative heading error
        err = mul(mul(ec, rc * conj), mul(rp, ep * conj))
        h = np.degrees(2 * np.arctan2(err[:, 3], err[:, 0]))
        return q("seg2")[:, 0], (h + 180) % 360 - 180

    fig, ax = plt.subplots(figsize=(9, 3.6))
    for label, args in (("per segment (magnetometer)", ["--heading", "magnetometer"]),
                        ("body-aware (auto)", ["--heading", "auto"]),
                        ("body-aware, no magnetometer", ["--no-mag"])):
        out = os.path.join(d, label.split()[0] + str(len(args)))
        run([filt, "--chain", toml, "--out-dir", out] + args)
        t, h = rel_heading(out)
        ax.plot(t, h, lw=0.9, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("relative heading error (°)")
    ax.set_title("Simulated arm in the lab field (seed 1): seg2–seg3 hinge")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default="build")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--plot")
    a = ap.parse_args()
    filt = os.path.join(a.build, "clients/filter_tool/mocap-filter")
    sim = os.path.join(a.build, "clients/sim/mocap-sim")
    with tempfile.TemporaryDirectory() as work:
        for kind in ("chain", "pendulum"):
            table(kind, filt, sim, a.seeds, work)
        if a.plot:
            plot(filt, sim, work, a.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
