#!/usr/bin/env python3
"""load_run.py — the capacity figures of docs/performance.md, from the real binaries.

One run = a fresh mocapd (generated config, free loopback ports, no BVH port), one
`mocap-sim stream` (K subjects x N raw nodes at R Hz) and one `mocap-client load`
(C clients, optionally S stalled ones). Timeline of a run:

    start mocapd, wait for its pose port
    start mocap-sim stream for warmup + measure + 1 s
    after warmup: CPU snapshot (every process, mocapd per thread), Stats
    mocap-client load --duration measure --json           (blocks; its rusage is its CPU)
    CPU snapshot, Stats, VmRSS                             -> rates over the window
    wait for the generator (its --sink-rate-stats JSON), 0.5 s drain, final Stats
    SIGTERM mocapd

Figures per run: samples the generator sent vs samples mocapd's workers processed (lost),
mocapd's drop counters, the load client's JSON (frames, gaps, drops, p50/p90/p99/max of
sink_send_us -> client receive), per-stage p50/p99 from Stats (cumulative over the run,
warm-up included), CPU of each process over the window (% of one core), mocapd CPU per
segment update (mocapd CPU / samples processed in the window), VmRSS, load average.

Usage (Release build):
    tests/bench/load_run.py --bin build/bin-dir [--groups all] [--out results.json] [--md tables.md]
    tests/bench/load_run.py --bin DIR --smoke       # CI check of the tool: exit 0 = fine
Groups: target subjects pf particles workers clients memory (memory = 10 min, not in "all").
--bin is a directory holding mocapd, mocap-sim and mocap-client, or the build tree (the
binaries are searched under it). Only python3's standard library is used.
"""

import argparse
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import time

CLK_TCK = os.sysconf("SC_CLK_TCK")
PAGE_KB = os.sysconf("SC_PAGE_SIZE") // 1024


# --------------------------------------------------------------------------------------
# Processes and /proc
# --------------------------------------------------------------------------------------

def find_binary(root, name):
    direct = os.path.join(root, name)
    if os.path.isfile(direct) and os.access(direct, os.X_OK):
        return direct
    for dirpath, _dirs, files in os.walk(root):
        if name in files:
            path = os.path.join(dirpath, name)
            if os.access(path, os.X_OK):
                return path
    raise SystemExit(f"load_run: {name} not found under {root}")


_HANDED_OUT = set()


def free_port():
    """A free port, never one already returned here (the kernel may hand one out twice)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port


def wait_for_port(port, limit_s):
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


NICE = 0  # --nice: applied to every process of a run (negative needs root)
RT_PRIORITY = 0  # --rt: SCHED_FIFO priority of every process of a run (0 = off; needs root)
PERF_STAT = False  # --perf-stat: futex calls, context switches and task clock per thread
PERF_EVENTS = "syscalls:sys_enter_futex,context-switches,task-clock"


def raise_nofile():
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))


def child_setup():
    raise_nofile()
    if NICE:
        # With sched_autogroup (the default on desktop and many server kernels) a nice
        # value only ranks threads within one session's group; groups share the CPU
        # equally. So each process gets its own session, and that group the nice value.
        os.setsid()
        try:
            with open("/proc/self/autogroup", "w") as f:
                f.write(str(NICE))
        except OSError:
            pass
        os.nice(NICE)
    if RT_PRIORITY:
        # Threads inherit the policy, so every thread of mocapd, of the generator and of the
        # load client runs before any ordinary task of the host (the kernel's RT throttling
        # still leaves other tasks 5 % of each core).
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))


def proc_cpu_s(pid):
    """user + system CPU seconds of a process (all threads), or None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / CLK_TCK
    except (OSError, IndexError):
        return None


def task_files(pid, name):
    """(tid, text of /proc/pid/task/tid/<name>) for every thread still alive."""
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []
    out = []
    for tid in tids:
        try:
            with open(f"/proc/{pid}/task/{tid}/{name}") as f:
                out.append((tid, f.read()))
        except OSError:
            pass
    return out


def thread_cpu_s(pid):
    """{ 'tid name': cpu_s } for every thread of a process."""
    out = {}
    for tid, text in task_files(pid, "stat"):
        name = text[text.index("(") + 1:text.rindex(")")]
        fields = text.rsplit(")", 1)[1].split()
        out[f"{tid} {name}"] = (int(fields[11]) + int(fields[12])) / CLK_TCK
    return out


def ctx_switches(pid):
    """Voluntary + involuntary context switches of every thread of a process (a sleeping
    worker woken per sample shows here, whatever the host's load)."""
    total = 0
    for _tid, text in task_files(pid, "status"):
        for line in text.splitlines():
            if line.startswith(("voluntary_ctxt_switches:", "nonvoluntary_ctxt_switches:")):
                total += int(line.split()[1])
    return total


def parse_perf_stat(path, updates):
    """perf stat -x, --per-thread output -> {event: {thread: per segment update}} plus a
    'total' per event."""
    out = {}
    try:
        lines = open(path).read().splitlines()
    except OSError:
        return None
    for line in lines:
        f = line.split(",")
        if len(f) < 4 or line.startswith("#"):
            continue
        thread, value, event = f[0], f[1], f[3]
        try:
            v = float(value)
        except ValueError:
            continue
        per = out.setdefault(event, {"total": 0.0})
        per[thread] = v / updates if updates else None
        per["total"] += v / updates if updates else 0.0
    return out


def vm_rss_kb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def loadavg():
    with open("/proc/loadavg") as f:
        return float(f.read().split()[0])


def stop(proc, grace_s=5.0):
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


# --------------------------------------------------------------------------------------
# One run
# --------------------------------------------------------------------------------------

def daemon_config(sink_port, pose_port, tmp, spec, out_port=0):
    """out_port: the live BVH port (protocol "bvh") or the HTTP port (protocol "ws")."""
    protocol = spec.get("protocol", "pose")
    params = spec.get("params", {})
    params_toml = "{ " + ", ".join(f"{k} = {v}" for k, v in params.items()) + " }" if params else "{}"
    return f"""[log]
level = "warn"
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:{sink_port}"
max_sinks = {spec['subjects'] + 8}
[pipeline]
workers = {spec.get('workers', 0)}
max_subjects = {max(64, spec['subjects'])}
[filter]
name = "{spec.get('filter', 'mocap')}"
params = {params_toml}
[skeleton]
calibration_dir = "{tmp}"
[serve]
pose_listen = "127.0.0.1:{pose_port}"
max_clients = 4096
threads = {spec.get('serve_threads', 1)}
client_queue_frames = {spec.get('client_queue_frames', 64)}
[outputs]
record_dir = "{tmp}"
""" + (f"""bvh_live = true
bvh_listen = "127.0.0.1:{out_port}"
bvh_max_clients = 4096
bvh_threads = {spec.get('bvh_threads', 1)}
bvh_subject = {spec.get('subject') or 0}
""" if protocol == "bvh" else "bvh_live = false\n") + (f"""[http]
listen = "127.0.0.1:{out_port}"
max_clients = 4096
threads = {spec.get('http_threads', 1)}
""" if protocol == "ws" else "")


OPTIONAL_SECTIONS = {}  # mocapd path -> extra config text it accepts


def optional_sections(mocapd, tmp):
    """Ports the run does not use are switched off, if this mocapd has them: builds with
    the web endpoint listen on 8080 by default, and two runs (or a running mocapd) would
    collide. An older mocapd rejects the unknown section, so ask --check-config first."""
    if mocapd not in OPTIONAL_SECTIONS:
        text = ""
        probe = os.path.join(tmp, "probe.toml")
        with open(probe, "w") as f:
            f.write("[http]\nenabled = false\n")
        if subprocess.run([mocapd, "--check-config", probe], capture_output=True).returncode == 0:
            text = "[http]\nenabled = false\n"
        OPTIONAL_SECTIONS[mocapd] = text
    return OPTIONAL_SECTIONS[mocapd]


def stats(client_bin, pose_port):
    r = subprocess.run([client_bin, "--connect", f"127.0.0.1:{pose_port}", "stats", "--json"],
                       capture_output=True, text=True, timeout=20)
    if r.returncode != 0:
        return None
    return json.loads(r.stdout)


def counter_sum(st, suffix):
    """Sum of every counter whose name ends with `suffix` (per-worker counters are summed)."""
    if st is None:
        return None
    return sum(v for k, v in st["counters"].items() if k == suffix or k.endswith("." + suffix))


def stage(st, name):
    if st is None:
        return None
    for l in st["latencies"]:
        if l["stage"] == name:
            return l
    return None


def run_once(bins, spec, log_dir):
    """spec: name, subjects, nodes, rate, filter, params, workers, clients, subject
    (None = all), stalled, warmup_s, measure_s, rss_every_s (memory run)."""
    raise_nofile()
    tmp = tempfile.mkdtemp(prefix="load_run_")
    sink_port, pose_port, out_port = free_port(), free_port(), free_port()
    protocol = spec.get("protocol", "pose")
    cfg = os.path.join(tmp, "mocapd.toml")
    with open(cfg, "w") as f:
        # A "ws" run has its own [http] section; the others switch HTTP off if it exists.
        f.write(daemon_config(sink_port, pose_port, tmp, spec, out_port) +
                ("" if protocol == "ws" else optional_sections(bins["mocapd"], tmp)))
    log = open(os.path.join(log_dir, f"{spec['name']}.mocapd.log"), "w")
    daemon = subprocess.Popen([bins["mocapd"], "--config", cfg], stdout=log, stderr=subprocess.STDOUT,
                              preexec_fn=child_setup)
    result = {"spec": spec, "nice": NICE, "rt": RT_PRIORITY, "loadavg_start": loadavg()}
    sim = None
    try:
        if not wait_for_port(pose_port, 10):
            log.flush()
            with open(log.name) as f:
                tail = f.read()[-2000:]
            raise RuntimeError(f"mocapd did not open its pose port; its output:\n{tail}")
        warmup, measure = spec.get("warmup_s", 3.0), spec.get("measure_s", 10.0)
        sim_cmd = [bins["mocap-sim"], "stream", "--connect", f"127.0.0.1:{sink_port}",
                   "--subjects", str(spec["subjects"]), "--nodes", str(spec.get("nodes", 15)),
                   "--rate", str(spec.get("rate", 100)), "--mode", "raw",
                   "--duration", str(warmup + measure + 1.5), "--sink-rate-stats"]
        sim = subprocess.Popen(sim_cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               preexec_fn=child_setup)
        time.sleep(warmup)

        cpu0 = {"mocapd": proc_cpu_s(daemon.pid), "sim": proc_cpu_s(sim.pid)}
        threads0 = thread_cpu_s(daemon.pid)
        ctx0 = ctx_switches(daemon.pid)
        st0 = stats(bins["mocap-client"], pose_port)
        perf = None
        if PERF_STAT:
            perf_out = os.path.join(tmp, "perf_stat.csv")
            perf = subprocess.Popen(["perf", "stat", "-x", ",", "--per-thread", "-e", PERF_EVENTS, "-p",
                                     str(daemon.pid), "-o", perf_out, "--", "sleep", str(measure)],
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        t0 = time.monotonic()
        load_port = pose_port if protocol == "pose" else out_port
        load_cmd = [bins["mocap-client"], "--connect", f"127.0.0.1:{load_port}", "load",
                    "--clients", str(spec.get("clients", 1)), "--duration", str(measure), "--json"]
        if protocol != "pose":
            load_cmd += ["--protocol", protocol]
        if spec.get("subject") is not None:
            load_cmd += ["--subject", str(spec["subject"])]
        if spec.get("stalled"):
            load_cmd += ["--stalled", str(spec["stalled"])]
        load_out = open(os.path.join(tmp, "load.json"), "w+")
        load_err = open(os.path.join(tmp, "load.err"), "w+")
        load = subprocess.Popen(load_cmd, stdout=load_out, stderr=load_err, text=True, preexec_fn=child_setup)
        rss_trace = []
        every = spec.get("rss_every_s")
        while True:
            # wait4 gives the load client's own CPU (rusage) when it ends.
            pid, status, ru = os.wait4(load.pid, os.WNOHANG)
            if pid == load.pid:
                load.returncode = os.waitstatus_to_exitcode(status)
                break
            if every and (not rss_trace or time.monotonic() - t0 - rss_trace[-1][0] >= every):
                rss_trace.append((round(time.monotonic() - t0, 1), vm_rss_kb(daemon.pid)))
            time.sleep(0.05)
        load_out.seek(0)
        load_err.seek(0)
        out, err = load_out.read(), load_err.read()
        wall = time.monotonic() - t0
        cpu1 = {"mocapd": proc_cpu_s(daemon.pid), "sim": proc_cpu_s(sim.pid)}
        threads1 = thread_cpu_s(daemon.pid)
        ctx1 = ctx_switches(daemon.pid)
        st1 = stats(bins["mocap-client"], pose_port)
        result["rss_kb"] = vm_rss_kb(daemon.pid)
        result["rss_trace"] = rss_trace
        result["loadavg_end"] = loadavg()
        try:
            result["load"] = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            result["load"] = None
            result["load_stderr"] = err[-2000:]
        result["load_exit"] = load.returncode

        sim_out, _ = sim.communicate(timeout=warmup + measure + 60)
        try:
            result["sim"] = json.loads(sim_out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            result["sim"] = None
        time.sleep(0.5)
        st2 = stats(bins["mocap-client"], pose_port)

        # CPU over the window, % of one core (the load client's from its rusage).
        result["window_s"] = wall
        result["load_client_cpu_pct"] = 100.0 * (ru.ru_utime + ru.ru_stime) / wall
        result["cpu_pct"] = {k: (100.0 * (cpu1[k] - cpu0[k]) / wall if cpu0[k] is not None and
                                 cpu1[k] is not None else None) for k in cpu0}
        result["threads_pct"] = {k: 100.0 * (v - threads0.get(k, 0.0)) / wall for k, v in threads1.items()}
        processed = (counter_sum(st1, "samples_processed") or 0) - (counter_sum(st0, "samples_processed") or 0)
        result["updates_per_s"] = processed / wall
        if perf is not None:
            perf.wait(30)
            result["perf_stat"] = parse_perf_stat(perf_out, processed * measure / wall)
        if processed > 0 and ctx0 is not None and ctx1 is not None:
            result["ctx_switches_per_update"] = (ctx1 - ctx0) / processed
        if processed > 0 and result["cpu_pct"]["mocapd"] is not None:
            result["mocapd_cpu_us_per_update"] = (cpu1["mocapd"] - cpu0["mocapd"]) * 1e6 / processed
        result["stats_final"] = st2
        if st2 is not None and result["sim"] is not None:
            result["samples_sent"] = result["sim"]["samples"]
            result["samples_processed"] = counter_sum(st2, "samples_processed")
            result["samples_lost"] = result["samples_sent"] - result["samples_processed"]
            # Split the loss: never decoded by ingest (on the way: a packet the generator
            # counted but did not send before it stopped, or the socket) vs inside mocapd.
            result["samples_decoded"] = counter_sum(st2, "samples")
            result["samples_lost_inside"] = result["samples_decoded"] - result["samples_processed"]
            result["drops"] = {k: counter_sum(st2, k) for k in
                               ("samples_dropped_full", "poses_dropped_full", "incomplete_samples",
                                "segments_late", "segments_stale", "frames_partial", "malformed_frames")}
            result["stages"] = {s["stage"]: s for s in st2["latencies"]}
            result["serve"] = {k: v for k, v in st2["counters"].items() if k.startswith("serve")}
    finally:
        if sim is not None and sim.poll() is None:
            stop(sim)
        result["mocapd_exit"] = stop(daemon)
        log.close()
    return result


# --------------------------------------------------------------------------------------
# Experiments
# --------------------------------------------------------------------------------------

def groups(measure_s):
    m = measure_s
    g = {}
    # Clients of every subject get 5000 frames/s: the default queue (64 frames) would hold
    # 13 ms of them, so these runs give them 1024 (200 ms), as a venue would.
    g["target"] = [dict(name="target_mocap_50", subjects=50, clients=2, client_queue_frames=1024, measure_s=m)]
    g["subjects"] = [dict(name=f"subjects_mocap_{k}", subjects=k, clients=1, subject=1, measure_s=m)
                     for k in (10, 25, 50, 100)]
    g["pf"] = [dict(name=f"pf256_{k}", subjects=k, filter="pf", params={"particles": 256}, clients=1,
                    subject=1, measure_s=m) for k in (25, 50, 75, 100, 125)]
    g["particles"] = [dict(name=f"particles_{p}", subjects=20, filter="pf", params={"particles": p},
                           clients=1, subject=1, measure_s=m) for p in (64, 128, 256, 512, 1024)]
    g["workers"] = [dict(name=f"workers{w}_mocap_50", subjects=50, workers=w, clients=1, subject=1, measure_s=m)
                    for w in (1, 2)] + \
                   [dict(name=f"workers{w}_pf256_50", subjects=50, workers=w, filter="pf",
                         params={"particles": 256}, clients=1, subject=1, measure_s=m) for w in (1, 2)]
    g["clients"] = [dict(name=f"clients_{c}", subjects=10, clients=c, subject=1, measure_s=m)
                    for c in (1, 10, 100, 300, 1000)] + \
                   [dict(name="clients_1000_stalled_10", subjects=10, clients=1000, subject=1, stalled=10,
                         measure_s=m)]
    # Fan-out on several serve threads (docs/performance.md; tests/bench/fanout_run.py runs
    # these interleaved and repeated): the pose stream's curve for 1, 2 and 4 threads, and
    # 1 000 clients of live BVH and of the WebSocket on 1 and 2 threads.
    g["fanout"] = [dict(name=f"fanout_pose_t{t}_{c}", subjects=10, clients=c, subject=1, serve_threads=t,
                        measure_s=m) for t in (1, 2, 4) for c in (10, 100, 300, 1000)] + \
                  [dict(name=f"fanout_bvh_t{t}_1000", subjects=10, clients=1000, subject=1, protocol="bvh",
                        bvh_threads=t, measure_s=m) for t in (1, 2)] + \
                  [dict(name=f"fanout_ws_t{t}_1000", subjects=10, clients=1000, subject=1, protocol="ws",
                        http_threads=t, measure_s=m) for t in (1, 2)]
    g["memory"] = [dict(name="memory_50_600s", subjects=50, clients=2, client_queue_frames=1024, measure_s=600,
                        rss_every_s=10)]
    g["smoke"] = [dict(name="smoke", subjects=3, nodes=15, clients=3, warmup_s=2.0, measure_s=3.0)]
    return g


def fmt(v, spec=".2f"):
    if v is None:
        return "–"
    return format(v, spec)


def row_common(r):
    load = r.get("load") or {}
    st = r.get("stages", {})
    q = st.get("queue_wait", {})
    fl = st.get("filter", {})
    return load, st, q, fl


def markdown(results):
    lines = ["| run | subjects | filter | workers | clients (+stalled) | sent | lost | lost in mocapd | drops (ring/pose/late/stale) "
             "| frames rx | gaps | srv drops | p50 ms | p90 ms | p99 ms | max ms | ingest p99 µs | queue p99 µs "
             "| filter p50/p99 µs | assembly p99 µs | CPU% mocapd | CPU% sim | CPU% load | µs CPU/update | ctx sw/update "
             "| RSS MiB | load avg |",
             "|" + "---|" * 27]
    for r in results:
        s = r["spec"]
        load, st, q, fl = row_common(r)
        d = r.get("drops", {})
        filt = s.get("filter", "mocap") + (f" {s['params']['particles']}" if "params" in s else "")
        lines.append("| " + " | ".join([
            s["name"], str(s["subjects"]), filt, str(s.get("workers", 0) or "2 (auto)"),
            f"{s.get('clients', 1)}" + (f" (+{s['stalled']})" if s.get("stalled") else ""),
            str(r.get("samples_sent", "–")), str(r.get("samples_lost", "–")),
            str(r.get("samples_lost_inside", "–")),
            "/".join(str(d.get(k, "–")) for k in ("samples_dropped_full", "poses_dropped_full",
                                                   "segments_late", "segments_stale")),
            str(load.get("frames", "–")), str(load.get("gaps", "–")), str(load.get("drops", "–")),
            fmt(load.get("p50_ms")), fmt(load.get("p90_ms")), fmt(load.get("p99_ms")), fmt(load.get("max_ms")),
            fmt(st.get("ingest", {}).get("p99_us"), ".0f"), fmt(q.get("p99_us"), ".0f"),
            fmt(fl.get("p50_us"), ".1f") + "/" + fmt(fl.get("p99_us"), ".1f"),
            fmt(st.get("assembly", {}).get("p99_us"), ".0f"),
            fmt(r["cpu_pct"].get("mocapd"), ".0f"), fmt(r["cpu_pct"].get("sim"), ".0f"),
            fmt(r.get("load_client_cpu_pct"), ".0f"),
            fmt(r.get("mocapd_cpu_us_per_update"), ".2f"),
            fmt(r.get("ctx_switches_per_update"), ".3f"),
            fmt((r.get("rss_kb") or 0) / 1024, ".1f"),
            f"{r['loadavg_start']:.1f}",
        ]) + " |")
    return "\n".join(lines)


def thread_table(r):
    items = sorted(r.get("threads_pct", {}).items(), key=lambda kv: -kv[1])
    return ", ".join(f"{k.split(' ', 1)[1]}[{k.split(' ', 1)[0]}] {v:.0f}%" for k, v in items if v >= 0.5)


def smoke_check(r):
    """Correctness of the tool, not timing: frames flow, the JSON has its fields, nothing is
    lost or skipped under a light load."""
    problems = []
    load = r.get("load")
    if load is None:
        return ["the load client printed no JSON: " + r.get("load_stderr", "")]
    for field in ("clients", "frames", "gaps", "drops", "p50_ms", "p90_ms", "p99_ms", "max_ms"):
        if field not in load:
            problems.append(f"load JSON lacks {field}")
    s = r["spec"]
    expected = s["clients"] * s["subjects"] * s.get("rate", 100) * s["measure_s"]
    if not load.get("frames") or load["frames"] < 0.5 * expected:
        problems.append(f"frames {load.get('frames')} < half of the expected {expected:.0f}")
    if load.get("gaps") != 0:
        problems.append(f"gaps {load.get('gaps')} under light load")
    if load.get("drops") != 0:
        problems.append(f"server drops {load.get('drops')} under light load")
    if r.get("samples_lost") is None:
        problems.append("no sample accounting (Stats or the generator's JSON missing)")
    else:
        if r["samples_lost_inside"] != 0:
            problems.append(f"samples decoded but not processed: {r['samples_lost_inside']}")
        # The generator counts its last instant even when --duration ends before the sink
        # packed it; more than one instant of every subject missing is a real loss.
        if r["samples_sent"] - r["samples_decoded"] > s["subjects"] * s.get("nodes", 15):
            problems.append(f"samples sent but not decoded: {r['samples_sent'] - r['samples_decoded']}")
    if r.get("sim") and r["sim"].get("syncs_skipped"):
        # The generator was not scheduled in time (a busy host): it sent fewer instants,
        # which is not a fault of mocapd or of the tool.
        print(f"load_run smoke: note: the generator skipped {r['sim']['syncs_skipped']} SYNCs "
              f"(host busy, load average {r['loadavg_start']})", file=sys.stderr)
    for st in ("ingest", "queue_wait", "filter", "assembly"):
        if not r.get("stages", {}).get(st, {}).get("count"):
            problems.append(f"Stats has no {st} latencies")
    if r["cpu_pct"].get("mocapd") is None:
        problems.append("no CPU sample of mocapd")
    if not r.get("rss_kb"):
        problems.append("no VmRSS of mocapd")
    if r.get("mocapd_exit") != 0:
        problems.append(f"mocapd exit status {r.get('mocapd_exit')}")
    return problems


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="", help="directory (or build tree) with mocapd, mocap-sim, mocap-client")
    ap.add_argument("--mocapd", default="", help="path of mocapd (overrides --bin)")
    ap.add_argument("--sim", default="", help="path of mocap-sim (overrides --bin)")
    ap.add_argument("--client", default="", help="path of mocap-client (overrides --bin)")
    ap.add_argument("--groups", default="all", help="comma list: target,subjects,pf,particles,workers,clients,"
                    "memory; all = every group but memory")
    ap.add_argument("--only", default="", help="comma list of run names (overrides --groups)")
    ap.add_argument("--measure-s", type=float, default=10.0, help="measurement window per run")
    ap.add_argument("--out", default="", help="write every result as JSON here")
    ap.add_argument("--md", default="", help="write the markdown tables here")
    ap.add_argument("--logs", default="", help="directory for mocapd logs (default: a temp dir)")
    ap.add_argument("--nice", type=int, default=0, help="nice value of every process of a run and of its "
                    "autogroup (e.g. -15 as root: other work on the host does not preempt the run)")
    ap.add_argument("--rt", type=int, default=0, help="SCHED_FIFO priority (1-99) of every process of a run, "
                    "as `chrt -f` or systemd's CPUSchedulingPolicy=fifo would give mocapd (root)")
    ap.add_argument("--perf-stat", action="store_true", help="also count futex calls, context switches "
                    "and task clock per mocapd thread over the window (perf stat; needs perf)")
    ap.add_argument("--smoke", action="store_true", help="small run; exit 1 if the tool's checks fail")
    a = ap.parse_args()

    global NICE, PERF_STAT, RT_PRIORITY
    NICE = a.nice
    RT_PRIORITY = a.rt
    PERF_STAT = a.perf_stat
    given = {"mocapd": a.mocapd, "mocap-sim": a.sim, "mocap-client": a.client}
    if not a.bin and not all(given.values()):
        raise SystemExit("load_run: give --bin DIR or all of --mocapd, --sim, --client")
    bins = {n: p or find_binary(a.bin, n) for n, p in given.items()}
    log_dir = a.logs or tempfile.mkdtemp(prefix="load_run_logs_")
    os.makedirs(log_dir, exist_ok=True)
    g = groups(a.measure_s)
    if a.smoke:
        names = ["smoke"]
    elif a.only:
        names = a.only.split(",")
    else:
        chosen = [x for x in g if x not in ("memory", "smoke")] if a.groups == "all" else a.groups.split(",")
        names = [s["name"] for x in chosen for s in g[x]]
    specs = {s["name"]: s for x in g.values() for s in x}
    unknown = [n for n in names if n not in specs]
    if unknown:
        raise SystemExit(f"load_run: unknown run(s) {unknown}; known: {sorted(specs)}")

    results = []
    for n in names:
        spec = specs[n]
        print(f"load_run: {n} ...", file=sys.stderr, flush=True)
        r = run_once(bins, spec, log_dir)
        results.append(r)
        load = r.get("load") or {}
        print(f"load_run: {n}: lost={r.get('samples_lost')} frames={load.get('frames')} gaps={load.get('gaps')} "
              f"p50={load.get('p50_ms')} p99={load.get('p99_ms')} cpu={r['cpu_pct']} "
              f"us/update={r.get('mocapd_cpu_us_per_update')} "
              f"ctx/update={r.get('ctx_switches_per_update')} rss_kb={r.get('rss_kb')} "
              f"threads: {thread_table(r)}", file=sys.stderr, flush=True)
        if a.out:
            with open(a.out, "w") as f:
                json.dump({"host": {"nproc": os.cpu_count()}, "results": results}, f, indent=1)

    md = markdown(results)
    print(md)
    for r in results:
        print(f"\n{r['spec']['name']} threads (% of one core over the window): {thread_table(r)}")
        if r.get("rss_trace"):
            print(f"{r['spec']['name']} VmRSS trace (s, KiB): {r['rss_trace']}")
    if a.md:
        with open(a.md, "w") as f:
            f.write(md + "\n")

    if a.smoke:
        problems = smoke_check(results[0])
        for p in problems:
            print(f"load_run smoke: FAIL: {p}", file=sys.stderr)
        if problems:
            print(f"load_run smoke: mocapd log in {log_dir}", file=sys.stderr)
            return 1
        print("load_run smoke: OK", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
