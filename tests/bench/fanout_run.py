#!/usr/bin/env python3
"""fanout_run.py — fan-out on several serve threads, measured side by side in one run.

Runs load_run.py's `fanout` group (10 subjects x 15 raw nodes x 100 Hz from mocap-sim, every
client subscribed to subject 1; generator, load client and mocapd on this host): the pose
stream with 10/100/300/1 000 clients on 1, 2 and 4 serve threads, and 1 000 clients of live
BVH ([outputs] bvh_threads) and of the viewer WebSocket ([http] threads) on 1 and 2. Rounds
are interleaved (every configuration once, then again), so the host's load drifts over all
of them alike; the table gives the median over the rounds of each figure.

    tests/bench/fanout_run.py --bin build --nice -15 --repeat 3 --out fanout.json

Columns: p50/p99 = median over the rounds of `mocap-client load`'s percentiles (pose and
WebSocket: sink send -> client read; BVH, whose lines carry no timestamp: a client's read
minus the first client's read of the same line, the fan-out spread); gaps = frames the
clients missed (SYNC jumps; BVH: line order), summed over the rounds; srv drops = frames the
server dropped from client queues or per-thread backlogs (Stats counters), summed; CPU % of
one core (mocapd; its serve threads; the load client), medians; load = the 1-minute load
average at the start of each round's run (min-max).
"""
import argparse
import json
import os
import statistics
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import load_run  # noqa: E402

DROP_COUNTERS = {
    "pose": ("serve.frames_dropped", "serve.backlog_dropped"),
    "bvh": ("bvh_live.frames_dropped", "bvh_live.backlog_dropped"),
    "ws": ("http.ws_frames_dropped", "http.ws_backlog_dropped"),
}
SERVE_THREAD_PREFIX = {"pose": "mocap-serve", "bvh": "mocap-bvh", "ws": "mocap-http"}


def server_drops(r):
    st = r.get("stats_final")
    if st is None:
        return None
    names = DROP_COUNTERS[r["spec"].get("protocol", "pose")]
    return sum(st["counters"].get(n, 0) for n in names)


def serve_cpu(r):
    prefix = SERVE_THREAD_PREFIX[r["spec"].get("protocol", "pose")]
    return sum(v for k, v in r.get("threads_pct", {}).items() if k.split(" ", 1)[-1].startswith(prefix))


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def summary(name, runs):
    s = runs[0]["spec"]
    loads = [r.get("load") or {} for r in runs]
    threads = s.get("serve_threads", s.get("bvh_threads", s.get("http_threads", 1)))
    drops = [server_drops(r) for r in runs]
    return {
        "name": name,
        "protocol": s.get("protocol", "pose"),
        "threads": threads,
        "clients": s["clients"],
        "rounds": len(runs),
        "p50_ms": median([l.get("p50_ms") for l in loads]),
        "p99_ms": median([l.get("p99_ms") for l in loads]),
        "p50_ms_all": [l.get("p50_ms") for l in loads],
        "p99_ms_all": [l.get("p99_ms") for l in loads],
        "frames_rx": median([l.get("frames") for l in loads]),
        "gaps": sum(l.get("gaps") or 0 for l in loads),
        "client_drops": sum(l.get("drops") or 0 for l in loads),
        "server_drops": None if None in drops else sum(drops),
        "connected_min": min(l.get("connected") or 0 for l in loads),
        "cpu_mocapd": median([r["cpu_pct"].get("mocapd") for r in runs]),
        "cpu_serve": median([serve_cpu(r) for r in runs]),
        "cpu_load_client": median([r.get("load_client_cpu_pct") for r in runs]),
        "loadavg": (min(r["loadavg_start"] for r in runs), max(r["loadavg_start"] for r in runs)),
    }


def fmt(v, spec=".2f"):
    return "–" if v is None else format(v, spec)


def markdown(rows):
    out = ["| service | threads | clients | p50 ms | p99 ms | p99 per round ms | frames rx | gaps | srv drops "
           "| CPU % mocapd / serve threads / load client | load avg |",
           "|---|---:|---:|---:|---:|---|---:|---:|---:|---|---|"]
    for r in rows:
        out.append("| " + " | ".join([
            {"pose": "pose", "bvh": "live BVH", "ws": "WebSocket"}[r["protocol"]], str(r["threads"]),
            f"{r['clients']:,}".replace(",", " "), fmt(r["p50_ms"]), fmt(r["p99_ms"]),
            " / ".join(fmt(v) for v in r["p99_ms_all"]), fmt(r["frames_rx"], ".0f"), str(r["gaps"]),
            fmt(r["server_drops"], ".0f"),
            f"{fmt(r['cpu_mocapd'], '.0f')} / {fmt(r['cpu_serve'], '.0f')} / {fmt(r['cpu_load_client'], '.0f')}",
            f"{r['loadavg'][0]:.1f}–{r['loadavg'][1]:.1f}",
        ]) + " |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True, help="build tree (or directory) with mocapd, mocap-sim, mocap-client")
    ap.add_argument("--nice", type=int, default=0, help="as load_run.py --nice (e.g. -15 as root)")
    ap.add_argument("--rt", type=int, default=0, help="as load_run.py --rt (SCHED_FIFO priority, root)")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved rounds; the table gives medians")
    ap.add_argument("--measure-s", type=float, default=10.0, help="measurement window per run")
    ap.add_argument("--only", default="", help="comma list of run names of the fanout group")
    ap.add_argument("--out", default="", help="write every result and the summary as JSON here")
    a = ap.parse_args()

    load_run.NICE = a.nice
    load_run.RT_PRIORITY = a.rt
    bins = {n: load_run.find_binary(a.bin, n) for n in ("mocapd", "mocap-sim", "mocap-client")}
    log_dir = tempfile.mkdtemp(prefix="fanout_run_logs_")
    specs = load_run.groups(a.measure_s)["fanout"]
    if a.only:
        wanted = a.only.split(",")
        specs = [s for s in specs if s["name"] in wanted]
    results = {s["name"]: [] for s in specs}
    for round_index in range(a.repeat):
        for s in specs:
            print(f"fanout_run: round {round_index + 1}/{a.repeat}: {s['name']} ...", file=sys.stderr, flush=True)
            r = load_run.run_once(bins, s, log_dir)
            results[s["name"]].append(r)
            load = r.get("load") or {}
            print(f"fanout_run: {s['name']}: connected={load.get('connected')} frames={load.get('frames')} "
                  f"gaps={load.get('gaps')} p50={load.get('p50_ms')} p99={load.get('p99_ms')} "
                  f"srv_drops={server_drops(r)} load={r['loadavg_start']:.1f} "
                  f"threads: {load_run.thread_table(r)}", file=sys.stderr, flush=True)
            if a.out:
                with open(a.out, "w") as f:
                    json.dump({"results": results}, f, indent=1)
    rows = [summary(n, runs) for n, runs in results.items()]
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"results": results, "summary": rows}, f, indent=1)
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
