#!/usr/bin/env python3
"""cluster_bench.py — the figures of docs/cluster.md, "Measured": the NATS path against the
direct pose service, side by side in one run, from the real binaries.

One run = one nats-server (user + password, monitoring port), one mocapd publishing to it
([cluster], generated config, free loopback ports), one `mocap-sim stream` (S subjects x 15
raw nodes at 100 Hz) for the whole run. Then, for each round and each client count C, in
alternating order: `mocap-client load --clients C` on the pose service and
`mocap-client --nats URL load --clients C` on the cluster, each for --seconds. Per transport
and C the table shows medians over the rounds: frames per client per second, gaps, drops
and the latency from the frame's sink_send_us to the client's receive (p50, p99), and for
the NATS runs the CPU nats-server spent per message it delivered (/proc, /varz out_msgs).
Before the loads, one quiet window measures what the publisher puts on the wire: messages and
bytes per subject per second (nats-server /varz in_msgs / in_bytes, heartbeats included).

Usage (Release build; nats-server from Debian):
    tests/bench/cluster_bench.py --bin build [--subjects 4] [--clients 1,10,100] [--rounds 3] [--seconds 6]
Only python3's standard library is used.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from load_run import find_binary, free_port, loadavg, proc_cpu_s, raise_nofile, stop, wait_for_port  # noqa: E402

USER, PASSWORD, SITE = "mocap", "bench-pw", "bench"


def varz(monitor_port):
    with urllib.request.urlopen(f"http://127.0.0.1:{monitor_port}/varz", timeout=5) as r:
        return json.load(r)


def config(tmp, sink_port, pose_port, nats_port, subjects):
    return f"""[log]
level = "warn"
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:{sink_port}"
max_sinks = {subjects + 8}
[pipeline]
max_subjects = {max(64, subjects)}
[skeleton]
calibration_dir = "{tmp}"
[serve]
pose_listen = "127.0.0.1:{pose_port}"
max_clients = 4096
client_queue_frames = 64
[outputs]
bvh_live = false
record_dir = "{tmp}"
[http]
enabled = false
[cluster]
nats_url = "nats://127.0.0.1:{nats_port}"
site = "{SITE}"
host_id = "bench"
user = "{USER}"
password = "{PASSWORD}"
queue_frames = 4096
"""


def load(bins, transport, pose_port, nats_port, clients, seconds):
    base = [bins["mocap-client"]]
    if transport == "nats":
        base += ["--nats", f"nats://127.0.0.1:{nats_port}", "--site", SITE, "--nats-user", USER,
                 "--nats-password", PASSWORD, "--connect-timeout", "10"]
    else:
        base += ["--connect", f"127.0.0.1:{pose_port}", "--connect-timeout", "10"]
    cmd = base + ["load", "--clients", str(clients), "--duration", str(seconds), "--json"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=seconds + 120)
    if not r.stdout.strip():
        raise RuntimeError(f"{' '.join(cmd)}: no output (exit {r.returncode}): {r.stderr[-500:]}")
    return json.loads(r.stdout)


def med(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def fmt(v, spec=".2f"):
    return "—" if v is None else format(v, spec)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True, help="build tree or directory with mocapd, mocap-sim, mocap-client")
    ap.add_argument("--nats-server", default="/usr/sbin/nats-server")
    ap.add_argument("--subjects", type=int, default=4)
    ap.add_argument("--clients", default="1,10,100")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=6.0)
    args = ap.parse_args()
    bins = {n: find_binary(args.bin, n) for n in ("mocapd", "mocap-sim", "mocap-client")}
    counts = [int(c) for c in args.clients.split(",")]
    raise_nofile()
    tmp = tempfile.mkdtemp(prefix="cluster_bench_")
    nats_port, monitor_port = free_port(), free_port()
    sink_port, pose_port = free_port(), free_port()
    logs = {n: open(os.path.join(tmp, n + ".log"), "w") for n in ("nats", "mocapd", "sim")}
    nats = subprocess.Popen([args.nats_server, "-a", "127.0.0.1", "-p", str(nats_port), "-m", str(monitor_port),
                             "--user", USER, "--pass", PASSWORD], stdout=logs["nats"], stderr=subprocess.STDOUT)
    procs = [nats]
    try:
        if not wait_for_port(nats_port, 15) or not wait_for_port(monitor_port, 15):
            raise RuntimeError("nats-server did not start; see " + logs["nats"].name)
        cfg = os.path.join(tmp, "mocapd.toml")
        with open(cfg, "w") as f:
            f.write(config(tmp, sink_port, pose_port, nats_port, args.subjects))
        daemon = subprocess.Popen([bins["mocapd"], "--config", cfg], stdout=logs["mocapd"], stderr=subprocess.STDOUT)
        procs.append(daemon)
        if not wait_for_port(pose_port, 15):
            raise RuntimeError("mocapd did not start; see " + logs["mocapd"].name)
        total = 10 + len(counts) * args.rounds * 2 * (args.seconds + 15)
        sim = subprocess.Popen([bins["mocap-sim"], "stream", "--connect", f"127.0.0.1:{sink_port}", "--subjects",
                                str(args.subjects), "--nodes", "15", "--rate", "100", "--mode", "raw", "--duration",
                                str(total)], stdout=logs["sim"], stderr=subprocess.STDOUT)
        procs.append(sim)
        time.sleep(3)  # warm-up: every subject assembling and published

        # What the publisher puts on the wire, before any subscriber exists.
        v0, t0 = varz(monitor_port), time.monotonic()
        time.sleep(5)
        v1, t1 = varz(monitor_port), time.monotonic()
        dt = t1 - t0
        msgs_per_subject = (v1["in_msgs"] - v0["in_msgs"]) / dt / args.subjects
        bytes_per_subject = (v1["in_bytes"] - v0["in_bytes"]) / dt / args.subjects

        results = {}  # (transport, clients) -> list of load JSON
        for rnd in range(args.rounds):
            for c in counts:
                order = ("direct", "nats") if rnd % 2 == 0 else ("nats", "direct")
                for transport in order:
                    v_before, cpu_before = varz(monitor_port), proc_cpu_s(nats.pid)
                    r = load(bins, transport, pose_port, nats_port, c, args.seconds)
                    v_after, cpu_after = varz(monitor_port), proc_cpu_s(nats.pid)
                    # What nats-server spent per message it delivered (publisher input included).
                    out = v_after["out_msgs"] - v_before["out_msgs"]
                    r["server_us_per_msg"] = (cpu_after - cpu_before) * 1e6 / out if out > 1000 else None
                    results.setdefault((transport, c), []).append(r)
                    print(f"round {rnd + 1} {transport:6} {c:5} clients: p50 {fmt(r['p50_ms'])} ms, "
                          f"p99 {fmt(r['p99_ms'])} ms, gaps {r['gaps']}, drops {r['drops']}", file=sys.stderr)
        la = loadavg()
    finally:
        for p in reversed(procs):
            stop(p)

    print(f"subjects {args.subjects} x 15 raw nodes at 100 Hz; {args.rounds} rounds of {args.seconds:g} s per "
          f"point, transports alternating; load average at the end {la:.2f}\n")
    print(f"Publisher on the wire: {msgs_per_subject:.1f} messages and {bytes_per_subject / 1000:.1f} kB per "
          f"subject per second ({bytes_per_subject * 8 / 1e6:.3f} Mbit/s per subject, heartbeats included)\n")
    print("| transport | clients | frames/s per client | gaps | drops | p50 ms | p99 ms | p99 NATS / direct "
          "| nats-server µs CPU per delivered message |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for c in counts:
        for transport in ("direct", "nats"):
            rs = results[(transport, c)]
            rate = med([r["frames"] / r["duration_s"] / max(c, 1) for r in rs])
            ratio = ""
            if transport == "nats":
                d, n = med([r["p99_ms"] for r in results[("direct", c)]]), med([r["p99_ms"] for r in rs])
                ratio = fmt(n / d if d and n else None)
            print(f"| {transport} | {c} | {fmt(rate, '.1f')} | {med([r['gaps'] for r in rs]):g} | "
                  f"{med([r['drops'] for r in rs]):g} | {fmt(med([r['p50_ms'] for r in rs]))} | "
                  f"{fmt(med([r['p99_ms'] for r in rs]))} | {ratio} | "
                  f"{fmt(med([r['server_us_per_msg'] for r in rs]) if transport == 'nats' else None)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
