#!/usr/bin/env python3
"""body_fusion.py — joint angles of body-aware fusion against the simulator's truth
(docs/fusion.md), from the real binaries.

The goal it measures: a simulated body walking for 10 minutes in the `lab` and `steel-floor`
magnetic environments with `[fusion] heading = "auto"` has every joint angle within 4° RMSE
of the truth, knee and elbow flexion within 2°, and an error in the last minute no larger
than in the first.

    body_fusion.py record --env lab|steel-floor|clean --duration S --out DIR [--seed N]
                          [--calibrate-s S]
    body_fusion.py eval DIR --heading magnetometer|joints|auto [--axis model|estimate]
                            [--offline] [--skip-s S]
    body_fusion.py table ROOT [--axes model,estimate] [--offline] [--breakdown] [--jobs N]
    body_fusion.py gap DIR OUT --at S --for S

record: a fresh mocapd on free loopback ports (generated config: raw recorder on, HTTP and
live BVH off, its calibration saved in DIR/calibration, [fusion] heading = "auto") fed by
`mocap-sim stream --magnetic-env ENV --truth DIR/truth.csv` (one subject, 15 raw nodes,
100 Hz, the walk: a T-pose for --calibrate-s = 2 s, a 1 s blend, then a 4 m circle at
1.2 m/s). It waits for mocapd's ports to accept, then for the simulator to exit, and stops
mocapd with SIGTERM (exit 0 required). Leaves DIR/raw-*.mocapraw, DIR/truth.csv,
DIR/mocapd.toml (the live config), DIR/record.json (what was run), DIR/*.log.

eval: `mocapd --config CFG --replay DIR/raw-*.mocapraw --angles-out EST.csv [--offline]`, CFG
being the recording's daemon settings with the chosen [fusion] (replay is deterministic and
fast, and calibrates itself from the T-pose as the live daemon did: auto_calibrate =
"t-pose", no calibration loaded). Rows of the estimate and the truth are joined on
(subject, sync). The first --skip-s seconds of each subject are not evaluated; time is the
truth's t_s since the subject's first row. The default skip is the recording's T-pose
(--calibrate-s, from record.json; 2 s when unknown) + 8 s: mocapd calibrates from 0.5 to
1.5 s into the T-pose, the walk blends in over 1 s after it, and 7 s are left for the
filters and the chain stage to settle (10 s for the simulator's default T-pose). Angle
differences are wrapped to (-180, 180]. Prints one JSON object: per angle the RMSE, the mean
error (bias), and the RMSE over the first minute (from the skip on) and the last minute of
the recording; the largest RMSE and its angle; knee and elbow flexion (the worse of left and
right); "first_min_deg" and "last_min_deg", the largest per-angle RMSE over the first and the
last minute; "goal": each threshold and "pass"; and "timing", how regularly the simulator
sent (the share of steps more than 2 ms off its period: a busy host makes it late).

gap: copies recording DIR to OUT without every node's samples from --at S to --at + --for S
(seconds after the first sample): a sink that lost its link for a while. The raw file is
otherwise byte-identical; truth.csv, record.json and mocapd.toml are copied. Needs
python3-protobuf and protoc (as body_real_convert.py).

table: eval of every recording in ROOT or its subdirectories (truth.csv + raw files)
x heading {magnetometer, joints, auto} x --axes; writes a markdown table (one row per
configuration) to stdout; --breakdown adds the per-angle RMSEs of the worst configuration and
of the heading = "auto" ones (the goal's); --json FILE keeps every eval's JSON.

Binaries: --bin DIR (a build tree or a directory holding them; default: build/ of this
checkout), or --mocapd / --sim. Python 3 with numpy (Debian's python3-numpy: run it with
/usr/bin/python3). Exit status: 0, or 1 when a tool fails; eval and table do not fail on a
missed goal (the JSON and the table say so).
"""

import argparse
import concurrent.futures
import glob
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from load_run import find_binary, free_port, stop, wait_for_port  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HEADINGS = ("magnetometer", "joints", "auto")
AXES = ("model", "estimate")
ENVS = ("clean", "lab", "steel-floor")
RATE_HZ = 100
CALIBRATE_S = 2.0  # mocap-sim stream's default T-pose
SETTLE_S = 8.0  # evaluated from the end of the T-pose + this (see the module comment)
MINUTE_S = 60.0

# The goal (docs/fusion.md).
GOAL_MAX_RMSE_DEG = 4.0
GOAL_FLEXION_RMSE_DEG = 2.0


# --------------------------------------------------------------------------------------
# Binaries, config, processes
# --------------------------------------------------------------------------------------

def binaries(a):
    root = a.bin or os.path.join(REPO, "build")
    return {"mocapd": a.mocapd or find_binary(root, "mocapd"), "mocap-sim": a.sim or find_binary(root, "mocap-sim")}


def daemon_config(calibration_dir, heading="auto", axis="model", record_dir=None, sink_port=0, pose_port=0):
    """The daemon's settings. Everything that shapes the solve (filter, assembly deadline,
    skeleton, automatic T-pose calibration) is at its shipped default, so the live run and
    every replay solve alike; only [fusion] differs between replays. With record_dir: the live
    run's config (loopback ports, the raw recorder on, one file)."""
    text = f"""[log]
level = "info"
stats_interval_s = 0
[pipeline]
workers = 2
max_subjects = 4
[fusion]
heading = "{heading}"
axis = "{axis}"
[skeleton]
calibration_dir = {json.dumps(calibration_dir)}
[http]
enabled = false
"""
    if record_dir is None:
        return text + '[outputs]\nbvh_live = false\n'
    return text + f"""[ingest]
sink_listen = "127.0.0.1:{sink_port}"
[serve]
pose_listen = "127.0.0.1:{pose_port}"
[outputs]
bvh_live = false
record_dir = {json.dumps(record_dir)}
raw_record = true
raw_rotate_mb = 0
raw_rotate_s = 0
"""


def wait_listening(process, port, limit_s):
    """True once 127.0.0.1:port accepts; False when the process exits first or at limit_s."""
    end = time.monotonic() + limit_s
    while process.poll() is None and time.monotonic() < end:
        if wait_for_port(port, 0.5):
            return True
    return False


def tail(path, n=3000):
    try:
        with open(path, errors="replace") as f:
            return f.read()[-n:]
    except OSError:
        return ""


def raw_files(rec_dir):
    """The recording's raw files in recording order: raw-<UTC start>-<index>.mocapraw."""
    def key(p):
        m = re.search(r"raw-(\d{8}-\d{6})-(\d+)\.mocapraw$", p)
        return (m.group(1), int(m.group(2))) if m else (p, 0)
    return sorted(glob.glob(os.path.join(rec_dir, "raw-*.mocapraw")), key=key)


# --------------------------------------------------------------------------------------
# record
# --------------------------------------------------------------------------------------

def record(bins, env, duration_s, out_dir, seed=1, calibrate_s=CALIBRATE_S):
    """Records one live session into out_dir; returns what record.json holds."""
    os.makedirs(out_dir, exist_ok=True)
    stale = raw_files(out_dir)
    if stale:
        raise SystemExit(f"body_fusion: {out_dir} already holds a recording ({os.path.basename(stale[0])})")
    cal = os.path.join(os.path.abspath(out_dir), "calibration")  # the live calibration, kept to look at
    os.makedirs(cal, exist_ok=True)
    sink_port, pose_port = free_port(), free_port()
    cfg = os.path.join(out_dir, "mocapd.toml")
    with open(cfg, "w") as f:
        f.write(daemon_config(cal, record_dir=os.path.abspath(out_dir), sink_port=sink_port, pose_port=pose_port))
    daemon_log = os.path.join(out_dir, "mocapd.log")
    sim_log = os.path.join(out_dir, "sim.log")
    truth = os.path.join(out_dir, "truth.csv")
    sim_cmd = [bins["mocap-sim"], "stream", "--connect", f"127.0.0.1:{sink_port}", "--subjects", "1", "--nodes",
               "15", "--rate", str(RATE_HZ), "--mode", "raw", "--motion", "walk", "--duration", str(duration_s),
               "--calibrate-s", str(calibrate_s), "--seed", str(seed), "--magnetic-env", env, "--truth", truth,
               "--sink-rate-stats"]
    t0 = time.monotonic()
    with open(daemon_log, "w") as dlog:
        daemon = subprocess.Popen([bins["mocapd"], "--config", cfg], stdout=dlog, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL)
    sim = None
    try:
        if not (wait_listening(daemon, sink_port, 30) and wait_listening(daemon, pose_port, 30)):
            raise SystemExit(f"body_fusion: mocapd did not listen; its log:\n{tail(daemon_log)}")
        with open(sim_log, "w") as slog:
            sim = subprocess.Popen(sim_cmd, stdout=subprocess.PIPE, stderr=slog, stdin=subprocess.DEVNULL, text=True)
            sim_out, _ = sim.communicate(timeout=duration_s + 120)
        if sim.returncode != 0:
            raise SystemExit(f"body_fusion: mocap-sim exited {sim.returncode}; its log:\n{tail(sim_log)}")
        try:
            sim_stats = json.loads(sim_out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            raise SystemExit(f"body_fusion: no stats line from mocap-sim:\n{sim_out[-2000:]}")
        if daemon.poll() is not None:
            raise SystemExit(f"body_fusion: mocapd exited {daemon.returncode} during the run; its log:\n"
                             f"{tail(daemon_log)}")
    finally:
        if sim is not None and sim.poll() is None:
            stop(sim)
        rc = stop(daemon, grace_s=30)
    if rc != 0:
        raise SystemExit(f"body_fusion: mocapd exited {rc} on SIGTERM (0 expected); its log:\n{tail(daemon_log)}")
    files = raw_files(out_dir)
    if not files:
        raise SystemExit(f"body_fusion: mocapd recorded nothing in {out_dir}; its log:\n{tail(daemon_log)}")
    meta = {"env": env, "seed": seed, "duration_s": duration_s, "calibrate_s": calibrate_s, "rate_hz": RATE_HZ,
            "raw_files": [os.path.basename(p) for p in files], "wall_s": round(time.monotonic() - t0, 1),
            "sim": {k: v for k, v in sim_stats.items() if k != "per_subject"},
            "sim_command": " ".join(["mocap-sim"] + sim_cmd[1:])}
    with open(os.path.join(out_dir, "record.json"), "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")
    return meta


# --------------------------------------------------------------------------------------
# eval
# --------------------------------------------------------------------------------------

def read_angles(path):
    """(angle names without "_deg", rows as float64: subject, sync, t_s, angles...)."""
    with open(path) as f:
        header = f.readline().strip().split(",")
    if header[:3] != ["subject", "sync", "t_s"] or len(header) < 4:
        raise SystemExit(f"body_fusion: {path} is not a joint-angle CSV (header {header[:4]})")
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return [h[:-4] if h.endswith("_deg") else h for h in header[3:]], rows


def replay(bins, rec_dir, heading, axis, offline, work):
    """Replays the recording under one [fusion] choice; returns (estimate CSV, mocapd's summary)."""
    files = raw_files(rec_dir)
    if not files:
        raise SystemExit(f"body_fusion: no raw-*.mocapraw in {rec_dir}")
    cal = os.path.join(work, "cal")
    os.makedirs(cal, exist_ok=True)
    cfg = os.path.join(work, "replay.toml")
    with open(cfg, "w") as f:
        f.write(daemon_config(cal, heading=heading, axis=axis))
    est = os.path.join(work, "estimate.csv")
    cmd = [bins["mocapd"], "--config", cfg, "--replay", *files, "--angles-out", est]
    if offline:
        cmd.append("--offline")
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"body_fusion: {' '.join(cmd)} exited {r.returncode}:\n{(r.stdout + r.stderr)[-3000:]}")
    summary = next((l for l in (r.stdout + r.stderr).splitlines() if "replayed" in l), "")
    return est, summary.strip()


def wrap_deg(d):
    """Angle differences wrapped to (-180, 180]."""
    return 180.0 - np.mod(180.0 - d, 360.0)


def rmse(d):
    return float(math.sqrt(np.mean(d * d))) if d.size else float("nan")


def compare(est_path, truth_path, skip_s):
    """Metrics of an estimate CSV against the truth CSV (see the module comment)."""
    names, est = read_angles(est_path)
    truth_names, truth = read_angles(truth_path)
    if names != truth_names:
        raise SystemExit(f"body_fusion: the estimate's columns differ from the truth's:\n{names}\n{truth_names}")
    # Time since each subject's first truth row.
    t_rel = np.empty(len(truth))
    for s in np.unique(truth[:, 0]):
        sel = truth[:, 0] == s
        t_rel[sel] = truth[sel, 2] - truth[sel, 2].min()
    # How regularly the simulator sent its SYNCs: on a loaded host its loop wakes late and the
    # sensors sample at irregular steps (and skip instants), which the estimate depends on.
    steps_ms = np.concatenate([np.diff(truth[truth[:, 0] == s, 2]) for s in np.unique(truth[:, 0])]) * 1e3
    period_ms = float(np.median(steps_ms)) if steps_ms.size else 0.0
    timing = {"period_ms": round(period_ms, 3),
              "irregular_steps": round(float(np.mean(np.abs(steps_ms - period_ms) > 2.0)), 4) if steps_ms.size else 0.0,
              "max_step_ms": round(float(steps_ms.max()), 1) if steps_ms.size else 0.0}
    key = lambda a: a[:, 0].astype(np.int64) * (1 << 40) + a[:, 1].astype(np.int64)  # noqa: E731
    _, ie, it = np.intersect1d(key(est), key(truth), assume_unique=False, return_indices=True)
    t = t_rel[it]
    diff = wrap_deg(est[ie, 3:] - truth[it, 3:])
    keep = (t >= skip_s) & np.all(np.isfinite(diff), axis=1)
    diff, t = diff[keep], t[keep]
    if not len(t):
        raise SystemExit(f"body_fusion: no rows to evaluate ({len(ie)} joined, skip {skip_s} s)")
    t_end = float(t.max())
    first = t < skip_s + MINUTE_S
    last = t > t_end - MINUTE_S
    angles = {}
    for j, name in enumerate(names):
        d = diff[:, j]
        angles[name] = {"rmse_deg": round(rmse(d), 3), "mean_deg": round(float(np.mean(d)), 3),
                        "first_min_rmse_deg": round(rmse(d[first]), 3),
                        "last_min_rmse_deg": round(rmse(d[last]), 3)}
    worst = max(angles, key=lambda n: angles[n]["rmse_deg"])

    def flexion(joint):
        sides = [angles[f"{side}_{joint}.flexion"]["rmse_deg"] for side in ("left", "right")
                 if f"{side}_{joint}.flexion" in angles]
        return max(sides) if sides else None

    first_min = max(a["first_min_rmse_deg"] for a in angles.values())
    last_min = max(a["last_min_rmse_deg"] for a in angles.values())
    out = {
        "skip_s": skip_s,
        "evaluated_s": round(t_end - skip_s, 2),
        "rows_truth": int(len(truth)),
        "rows_estimate": int(len(est)),
        "rows_joined": int(len(ie)),
        "rows_evaluated": int(len(t)),
        "max_rmse_deg": angles[worst]["rmse_deg"],
        "worst_angle": worst,
        "knee_flexion_rmse_deg": flexion("knee"),
        "elbow_flexion_rmse_deg": flexion("elbow"),
        "first_min_deg": first_min,
        "last_min_deg": last_min,
        "rms_all_deg": round(rmse(diff.ravel()), 3),
        "timing": timing,
        "angles": angles,
    }
    goal = {
        "max_rmse_le_4": out["max_rmse_deg"] <= GOAL_MAX_RMSE_DEG,
        "knee_flexion_le_2": out["knee_flexion_rmse_deg"] is not None and
        out["knee_flexion_rmse_deg"] <= GOAL_FLEXION_RMSE_DEG,
        "elbow_flexion_le_2": out["elbow_flexion_rmse_deg"] is not None and
        out["elbow_flexion_rmse_deg"] <= GOAL_FLEXION_RMSE_DEG,
        "last_min_le_first_min": last_min <= first_min,
    }
    goal["pass"] = all(goal.values())
    out["goal"] = goal
    return out


def record_meta(rec_dir):
    try:
        with open(os.path.join(rec_dir, "record.json")) as f:
            return json.load(f)
    except (OSError, ValueError):
        return {}


def default_skip_s(rec_dir):
    return float(record_meta(rec_dir).get("calibrate_s", CALIBRATE_S)) + SETTLE_S


def evaluate(bins, rec_dir, heading, axis="model", offline=False, skip_s=None):
    if skip_s is None:
        skip_s = default_skip_s(rec_dir)
    work = tempfile.mkdtemp(prefix="body_fusion_eval_")
    try:
        t0 = time.monotonic()
        est, summary = replay(bins, rec_dir, heading, axis, offline, work)
        replay_s = time.monotonic() - t0
        out = compare(est, os.path.join(rec_dir, "truth.csv"), skip_s)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    meta = record_meta(rec_dir)
    head = {"recording": os.path.abspath(rec_dir), "env": meta.get("env"), "seed": meta.get("seed"),
            "calibrate_s": meta.get("calibrate_s", CALIBRATE_S),
            "syncs_skipped": meta.get("sim", {}).get("syncs_skipped"),
            "heading": heading, "axis": axis, "offline": offline, "replay": summary, "replay_s": round(replay_s, 2)}
    return {**head, **out}


# --------------------------------------------------------------------------------------
# gap
# --------------------------------------------------------------------------------------

def cut_gap(rec_dir, out_dir, at_s, for_s):
    """Writes rec_dir's recording to out_dir without the samples in [at_s, at_s + for_s)."""
    from body_real_convert import load_pb2, read_varint  # noqa: E402 (protobuf only for this command)
    pb2 = load_pb2(None)
    files = raw_files(rec_dir)
    if not files:
        raise SystemExit(f"body_fusion: no raw-*.mocapraw in {rec_dir}")
    os.makedirs(out_dir, exist_ok=False)
    for name in ("truth.csv", "record.json", "mocapd.toml"):
        if os.path.isfile(os.path.join(rec_dir, name)):
            shutil.copy(os.path.join(rec_dir, name), out_dir)
    t0, dropped, kept = None, 0, 0
    for path in files:
        with open(path, "rb") as f:
            data = f.read()
        if data[:8] != b"MOCAPRAW":
            raise SystemExit(f"body_fusion: {path}: no MOCAPRAW magic")
        out, pos = [data[:8]], 8
        while pos < len(data):
            start = pos
            n, pos = read_varint(data, pos)
            rec = pb2.RawRecord()
            rec.ParseFromString(data[pos:pos + n])
            pos += n
            if rec.HasField("sample"):
                t0 = rec.sample.t_us if t0 is None else t0
                if at_s <= (rec.sample.t_us - t0) * 1e-6 < at_s + for_s:
                    dropped += 1
                    continue
                kept += 1
            out.append(data[start:pos])
        with open(os.path.join(out_dir, os.path.basename(path)), "wb") as f:
            f.write(b"".join(out))
    return {"recording": os.path.abspath(rec_dir), "out": os.path.abspath(out_dir), "at_s": at_s, "for_s": for_s,
            "samples_dropped": dropped, "samples_kept": kept}


# --------------------------------------------------------------------------------------
# table
# --------------------------------------------------------------------------------------

def recordings(root):
    if os.path.isfile(os.path.join(root, "truth.csv")) and raw_files(root):
        return [root]
    found = [d for d in sorted(glob.glob(os.path.join(root, "*")))
             if os.path.isfile(os.path.join(d, "truth.csv")) and raw_files(d)]
    order = {e: i for i, e in enumerate(ENVS)}

    return sorted(found, key=lambda d: (order.get(record_meta(d).get("env"), len(order)), d))


def fmt(v):
    return "—" if v is None else f"{v:.2f}"


def markdown(results):
    lines = ["| environment | T-pose (s) | heading | axis | max angle RMSE (°) | worst angle | knee flexion (°) | "
             "elbow flexion (°) | first minute (°) | last minute (°) | goal |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in results:
        g = r["goal"]
        missed = [k for k, v in g.items() if k != "pass" and not v]
        verdict = "pass" if g["pass"] else "fail: " + ", ".join(
            {"max_rmse_le_4": "max > 4°", "knee_flexion_le_2": "knee > 2°", "elbow_flexion_le_2": "elbow > 2°",
             "last_min_le_first_min": "last > first"}[k] for k in missed)
        env = (r["env"] or os.path.basename(r["recording"])) + (" (offline)" if r["offline"] else "")
        lines.append(f"| {env} | {r['calibrate_s']:g} | {r['heading']} | {r['axis']} | {fmt(r['max_rmse_deg'])} | "
                     f"{r['worst_angle']} | "
                     f"{fmt(r['knee_flexion_rmse_deg'])} | {fmt(r['elbow_flexion_rmse_deg'])} | "
                     f"{fmt(r['first_min_deg'])} | {fmt(r['last_min_deg'])} | {verdict} |")
    return "\n".join(lines)


def breakdown(r):
    """Per-angle RMSE, bias, first and last minute of one configuration, worst first."""
    env = r["env"] or os.path.basename(r["recording"])
    lines = [f"{env}, heading = {r['heading']}, axis = {r['axis']}{', offline' if r['offline'] else ''}:", "",
             "| angle | RMSE (°) | mean error (°) | first minute (°) | last minute (°) |",
             "| --- | --- | --- | --- | --- |"]
    for name, a in sorted(r["angles"].items(), key=lambda kv: -kv[1]["rmse_deg"]):
        lines.append(f"| {name} | {a['rmse_deg']:.2f} | {a['mean_deg']:+.2f} | {a['first_min_rmse_deg']:.2f} | "
                     f"{a['last_min_rmse_deg']:.2f} |")
    return "\n".join(lines)


def table(bins, root, axes, offline, skip_s, jobs):
    recs = recordings(root)
    if not recs:
        raise SystemExit(f"body_fusion: no recording (truth.csv + raw-*.mocapraw) in {root} or its subdirectories")
    configs = [(d, h, x) for d in recs for h in HEADINGS for x in axes]
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = [pool.submit(evaluate, bins, d, h, x, offline, skip_s) for d, h, x in configs]
        results = []
        for (d, h, x), fut in zip(configs, futures):
            r = fut.result()
            print(f"body_fusion: {os.path.basename(d)} {h} {x}: max {r['max_rmse_deg']} ({r['worst_angle']}), "
                  f"replay {r['replay_s']} s", file=sys.stderr, flush=True)
            results.append(r)
    return results


# --------------------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="", help="build tree or directory with mocapd and mocap-sim (default: build/)")
    ap.add_argument("--mocapd", default="", help="path of mocapd (overrides --bin)")
    ap.add_argument("--sim", default="", help="path of mocap-sim (overrides --bin)")
    sub = ap.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="a live session: raw recording + truth")
    rec.add_argument("--env", required=True, help="magnetic environment: clean | lab | steel-floor | FILE.toml")
    rec.add_argument("--duration", type=float, required=True, help="seconds of simulation (T-pose included)")
    rec.add_argument("--out", required=True, help="directory for the recording (created; must hold none yet)")
    rec.add_argument("--seed", type=int, default=1)
    rec.add_argument("--calibrate-s", type=float, default=CALIBRATE_S, help="the simulator's opening T-pose")
    ev = sub.add_parser("eval", help="replay one recording under one [fusion] choice, JSON to stdout")
    ev.add_argument("dir")
    ev.add_argument("--heading", required=True, choices=HEADINGS)
    ev.add_argument("--axis", default="model", choices=AXES)
    ev.add_argument("--offline", action="store_true", help="mocapd --replay --offline (forward-backward re-solve)")
    ev.add_argument("--skip-s", type=float, default=None, help="seconds not evaluated at the start "
                    "(default: the recording's T-pose + 8 s)")
    tb = sub.add_parser("table", help="eval of every recording x heading x axis, markdown to stdout")
    tb.add_argument("root")
    tb.add_argument("--axes", default=",".join(AXES), help="comma list of model, estimate")
    tb.add_argument("--offline", action="store_true")
    tb.add_argument("--skip-s", type=float, default=None, help="as eval's")
    tb.add_argument("--breakdown", action="store_true", help="also the per-angle RMSEs of the worst "
                    "configuration and of every heading = auto one")
    tb.add_argument("--json", default="", help="write every eval's JSON here")
    tb.add_argument("--jobs", type=int, default=1, help="replays at once")
    gp = sub.add_parser("gap", help="a copy of a recording without every node's samples for a while")
    gp.add_argument("dir")
    gp.add_argument("out", help="directory for the copy (created; must not exist)")
    gp.add_argument("--at", type=float, required=True, help="start of the gap, s after the first sample")
    gp.add_argument("--for", dest="for_s", type=float, required=True, help="its length, s")
    a = ap.parse_args()
    if a.command == "gap":
        print(json.dumps(cut_gap(a.dir, a.out, a.at, a.for_s)))
        return 0
    bins = binaries(a)

    if a.command == "record":
        meta = record(bins, a.env, a.duration, a.out, a.seed, a.calibrate_s)
        print(json.dumps(meta))
    elif a.command == "eval":
        print(json.dumps(evaluate(bins, a.dir, a.heading, a.axis, a.offline, a.skip_s)))
    else:
        axes = [x for x in a.axes.split(",") if x]
        bad = [x for x in axes if x not in AXES]
        if bad:
            raise SystemExit(f"body_fusion: unknown axis {bad}; known: {list(AXES)}")
        results = table(bins, a.root, axes, a.offline, a.skip_s, a.jobs)
        print(markdown(results))
        if a.breakdown:
            worst = max(results, key=lambda r: r["max_rmse_deg"])
            for r in [worst] + [r for r in results if r["heading"] == "auto" and r is not worst]:
                print("\n" + breakdown(r))
        if a.json:
            with open(a.json, "w") as f:
                json.dump(results, f, indent=1)
                f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
