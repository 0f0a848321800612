#!/usr/bin/env python3
"""soak.py — the long run of docs/reliability.md ("Soak"): legitimate work beside a hostile
mix, on the real binaries, watching the daemon's memory, file descriptors and CPU.

Legitimate work (what must not suffer):
    mocap-sim stream: 2 subjects x 15 raw nodes at 100 Hz
    rotating raw recordings ([outputs].raw_record, a new file every --rotate-s seconds)
    one BVH recording, started at the beginning and stopped at the end by control requests
    mocap-client load: --clients subscriptions of every subject (frames, gaps, drops)

Hostile mix, running beside it the whole time (each kind in its own thread, reconnecting
whenever the daemon closes it):
    churn      pose connections re-sending Subscribe for thousands of subject ids, just
               inside the per-connection message rate limit, without a token
    slow       sink connections that send one byte every 2 s; pose, live-BVH and WebSocket
               connections that subscribe and never read
    garbage    random bytes to the sink, pose, live-BVH and HTTP ports
    tokens     control requests with wrong tokens, on a new connection each time

Every --sample-s seconds: the daemon's VmRSS, open file descriptors, threads and CPU.
At the end: frames the legitimate clients lost (gaps + queue drops), the BVH recording's
frame count against its MOTION lines, that every raw file replays (mocapd --replay), the
daemon's counters of what it refused, and its exit status.

Usage (Release build):
    tests/bench/soak.py --bin build [--duration-s 1800] [--md soak.md] [--json soak.json]
    tests/bench/soak.py --bin build --smoke      # 20 s, 10 clients: checks the tool itself
Exit status: 0 when no legitimate frame was lost (not judged by --smoke), every file is valid
and mocapd exited 0.
Only python3's standard library and the repository's Python client (for the protobuf
messages) are used.
"""

import argparse
import json
import os
import random
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "..", "clients", "python"))

import load_run  # noqa: E402  (free_port, wait_for_port, /proc readers, stop)
from mocapd_client.framing import frame_message  # noqa: E402
from mocapd_client.proto import load_mocap_pb2  # noqa: E402

pb = load_mocap_pb2()
TOKEN = "soak-control-token-0123456789"
CHURN_PER_S = 18.0  # below [serve] max_client_messages_per_s (20 by default)


def config(ports, tmp, rotate_s):
    return f"""[log]
level = "info"
stats_interval_s = 60
[ingest]
sink_listen = "127.0.0.1:{ports['sink']}"
[pipeline]
max_subjects = 4
[skeleton]
calibration_dir = "{tmp}/calibration"
[serve]
pose_listen = "127.0.0.1:{ports['pose']}"
max_clients = 1024
[control]
token = "{TOKEN}"
[outputs]
bvh_live = true
bvh_listen = "127.0.0.1:{ports['bvh']}"
raw_record = true
raw_rotate_s = {rotate_s}
record_dir = "{tmp}/record"
[http]
listen = "127.0.0.1:{ports['http']}"
"""


# --------------------------------------------------------------------------------------
# The hostile mix
# --------------------------------------------------------------------------------------

class Hostile:
    """Threads that attack until stop is set; `counts` says what each managed to do."""

    def __init__(self, ports, stop, scale):
        self.ports, self.stop, self.scale = ports, stop, scale
        self.counts = {}
        self.lock = threading.Lock()
        self.threads = []

    def count(self, name, n=1):
        with self.lock:
            self.counts[name] = self.counts.get(name, 0) + n

    def start(self):
        s = self.scale
        kinds = [(self.churn, 8 * s), (self.slow_sink, 8 * s), (self.never_read_pose, 4 * s),
                 (self.never_read_bvh, 4 * s), (self.never_read_ws, 4 * s), (self.garbage, 1),
                 (self.bad_tokens, 1)]
        for fn, n in kinds:
            for i in range(n):
                t = threading.Thread(target=self.forever, args=(fn, i), daemon=True)
                t.start()
                self.threads.append(t)

    def join(self):
        for t in self.threads:
            t.join(10)

    def forever(self, fn, i):
        while not self.stop.is_set():
            try:
                fn(i)
            except OSError:
                self.count(fn.__name__ + "_closed_by_daemon")
            self.stop.wait(0.2)

    def connect(self, port):
        s = socket.create_connection(("127.0.0.1", port), timeout=5)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        return s

    def churn(self, i):
        with self.connect(self.ports["pose"]) as s:
            s.settimeout(0.05)
            many = pb.ClientMessage()
            many.subscribe.subject_ids.extend(range(1000 + i, 5000 + i))
            one = pb.ClientMessage()
            one.subscribe.subject_ids.append(1)
            msgs = [frame_message(many.SerializeToString()), frame_message(one.SerializeToString())]
            k = 0
            next_send = time.monotonic()
            while not self.stop.is_set():
                # Inside the per-connection rate limit (20 messages/s by default): the attack
                # costs the daemon work without breaking a rule.
                if time.monotonic() >= next_send:
                    s.sendall(msgs[k % 2])
                    k += 1
                    next_send += 1.0 / CHURN_PER_S
                    self.count("churn_subscribes")
                try:
                    if s.recv(65536) == b"":
                        raise OSError("closed")
                except socket.timeout:
                    pass

    def slow_sink(self, i):
        with self.connect(self.ports["sink"]) as s:
            while not self.stop.is_set():
                s.sendall(bytes([0x55]))
                self.count("slow_sink_bytes")
                if self.stop.wait(2.0):
                    return

    def hold(self, s):
        """Never reads; returns when the daemon closed the connection (a send fails)."""
        while not self.stop.wait(2.0):
            s.sendall(b"")  # raises once the peer reset the connection
            try:
                s.settimeout(0.001)
                if s.recv(1, socket.MSG_PEEK) == b"":
                    raise OSError("closed")
            except socket.timeout:
                pass
            except BlockingIOError:
                pass

    def never_read_pose(self, i):
        with self.connect(self.ports["pose"]) as s:
            sub = pb.ClientMessage()
            sub.subscribe.SetInParent()
            s.sendall(frame_message(sub.SerializeToString()))
            self.count("never_read_pose_connections")
            self.hold(s)

    def never_read_bvh(self, i):
        with self.connect(self.ports["bvh"]) as s:
            self.count("never_read_bvh_connections")
            self.hold(s)

    def never_read_ws(self, i):
        with self.connect(self.ports["http"]) as s:
            key = "dGhlIHNhbXBsZSBub25jZQ=="
            s.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{self.ports['http']}\r\nUpgrade: websocket\r\n"
                       f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
                      .encode())
            self.count("never_read_ws_connections")
            self.hold(s)

    def garbage(self, i):
        rnd = random.Random(i)
        while not self.stop.is_set():
            for port in (self.ports["sink"], self.ports["pose"], self.ports["bvh"], self.ports["http"]):
                try:
                    with self.connect(port) as s:
                        s.sendall(rnd.randbytes(4096))
                        self.count("garbage_sends")
                except OSError:
                    self.count("garbage_refused")
            self.stop.wait(0.5)

    def bad_tokens(self, i):
        req = pb.ClientMessage()
        req.control.token = "wrong-token-" + "x" * 20
        req.control.stop_recording.SetInParent()
        data = frame_message(req.SerializeToString())
        while not self.stop.is_set():
            try:
                with self.connect(self.ports["pose"]) as s:
                    s.sendall(data)
                    self.count("bad_token_attempts")
                    s.settimeout(2)
                    s.recv(4096)
            except OSError:
                self.count("bad_token_refused_connections")
            self.stop.wait(0.01)


# --------------------------------------------------------------------------------------
# Checks of what the legitimate side produced
# --------------------------------------------------------------------------------------

def bvh_consistent(path):
    """(declared frames, MOTION lines) of a BVH file."""
    declared, lines, in_motion = None, 0, False
    with open(path) as f:
        for line in f:
            if in_motion:
                if line.startswith("Frames:"):
                    declared = int(line.split()[1])
                elif line.startswith("Frame Time:"):
                    continue
                elif line.strip():
                    lines += 1
            elif line.startswith("MOTION"):
                in_motion = True
    return declared, lines


def control(client_bin, pose_port, *args):
    r = subprocess.run([client_bin, "--connect", f"127.0.0.1:{pose_port}", "control", "--token", TOKEN, *args],
                       capture_output=True, text=True, timeout=30)
    return r.returncode, (r.stdout + r.stderr).strip()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="", help="directory (or build tree) with mocapd, mocap-sim, mocap-client")
    ap.add_argument("--mocapd", default="", help="path of mocapd (overrides --bin)")
    ap.add_argument("--sim", default="", help="path of mocap-sim (overrides --bin)")
    ap.add_argument("--client", default="", help="path of mocap-client (overrides --bin)")
    ap.add_argument("--duration-s", type=float, default=1800.0)
    ap.add_argument("--clients", type=int, default=100)
    ap.add_argument("--sample-s", type=float, default=60.0)
    ap.add_argument("--rotate-s", type=float, default=60.0, help="raw recording rotation (10 s at least)")
    ap.add_argument("--hostile-scale", type=int, default=2, help="multiplies the hostile connections")
    ap.add_argument("--md", default="")
    ap.add_argument("--json", default="")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory (logs, recordings)")
    ap.add_argument("--smoke", action="store_true", help="20 s, 10 clients, sample every 5 s, rotate every 10 s")
    a = ap.parse_args()
    if a.smoke:
        a.duration_s, a.clients, a.sample_s, a.rotate_s, a.hostile_scale = 20.0, 10, 5.0, 10.0, 1
    given = {"mocapd": a.mocapd, "mocap-sim": a.sim, "mocap-client": a.client}
    bins = {n: given[n] or load_run.find_binary(a.bin, n) for n in given}
    load_run.raise_nofile()

    tmp = tempfile.mkdtemp(prefix="soak_")
    os.makedirs(f"{tmp}/calibration")
    os.makedirs(f"{tmp}/record")
    ports = {k: load_run.free_port() for k in ("sink", "pose", "bvh", "http")}
    cfg = f"{tmp}/mocapd.toml"
    with open(cfg, "w") as f:
        f.write(config(ports, tmp, a.rotate_s))
    log = open(f"{tmp}/mocapd.log", "w")
    daemon = subprocess.Popen([bins["mocapd"], "--config", cfg], stdout=log, stderr=subprocess.STDOUT,
                              preexec_fn=load_run.child_setup)
    result = {"duration_s": a.duration_s, "clients": a.clients, "tmp": tmp, "samples": []}
    ok = True
    stop = threading.Event()
    hostile = Hostile(ports, stop, a.hostile_scale)
    try:
        for p in ports.values():
            if not load_run.wait_for_port(p, 15):
                log.flush()
                with open(f"{tmp}/mocapd.log") as f:
                    raise SystemExit(f"soak: mocapd did not open port {p}; its log:\n{f.read()[-2000:]}")
        sim = subprocess.Popen([bins["mocap-sim"], "stream", "--connect", f"127.0.0.1:{ports['sink']}",
                                "--subjects", "2", "--nodes", "15", "--rate", "100", "--mode", "raw",
                                "--duration", str(a.duration_s + 8), "--sink-rate-stats"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               preexec_fn=load_run.child_setup)
        time.sleep(2.0)  # the sink connects and frames start before anything is measured
        bvh_path = f"{tmp}/record/soak.bvh"
        rc, text = control(bins["mocap-client"], ports["pose"], "record-start", "--path", bvh_path)
        result["record_start"] = text
        load = subprocess.Popen([bins["mocap-client"], "--connect", f"127.0.0.1:{ports['pose']}", "load",
                                 "--clients", str(a.clients), "--duration", str(a.duration_s), "--json"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=load_run.child_setup)
        hostile.start()
        t0 = time.monotonic()
        cpu_prev, t_prev = load_run.proc_cpu_s(daemon.pid), t0
        while load.poll() is None:
            time.sleep(min(a.sample_s, 1.0))
            now = time.monotonic()
            if now - t_prev < a.sample_s and load.poll() is None:
                continue
            cpu = load_run.proc_cpu_s(daemon.pid)
            try:
                fds = len(os.listdir(f"/proc/{daemon.pid}/fd"))
                threads = len(os.listdir(f"/proc/{daemon.pid}/task"))
            except OSError:
                fds = threads = None
            row = {"t_s": round(now - t0, 1), "rss_mb": round((load_run.vm_rss_kb(daemon.pid) or 0) / 1024, 1),
                   "fds": fds, "threads": threads,
                   "cpu_pct": round(100 * (cpu - cpu_prev) / (now - t_prev), 1) if cpu and cpu_prev else None,
                   "loadavg": load_run.loadavg()}
            result["samples"].append(row)
            print(json.dumps(row), flush=True)
            cpu_prev, t_prev = cpu, now
        out, err = load.communicate()
        stop.set()
        hostile.join()
        result["hostile"] = hostile.counts
        result["load"] = json.loads(out) if load.returncode == 0 and out.strip() else {"error": err[-2000:]}
        rc, text = control(bins["mocap-client"], ports["pose"], "record-stop")
        result["record_stop"] = text
        sim_out, _ = sim.communicate(timeout=60)
        result["sim"] = sim_out.strip().splitlines()[-1] if sim_out.strip() else ""
        result["stats"] = load_run.stats(bins["mocap-client"], ports["pose"])
    finally:
        stop.set()
        result["mocapd_exit"] = load_run.stop(daemon, 20)
        log.close()

    # Legitimate clients: every frame the pipeline produced reached every client.
    ld = result.get("load", {})
    lost = None
    if "missing_frames" in ld:
        # A frame dropped from a client's queue is also missing at the client: the count is
        # the frames a legitimate client never received, whatever the cause.
        lost = int(ld["missing_frames"])
    result["frames_lost_by_clients"] = lost
    ok &= ld.get("connected") == a.clients and ld.get("frames", 0) > 0
    # The smoke run checks the tool, on any machine and under the sanitizers, where a starved
    # client may fall behind: frames lost are reported there, and judged in the real run.
    if not a.smoke:
        ok &= lost == 0 and ld.get("closed_early") == 0
    # The BVH recording: Frames: matches its lines.
    if os.path.exists(bvh_path):
        declared, lines = bvh_consistent(bvh_path)
        result["bvh"] = {"declared": declared, "lines": lines}
        ok &= declared == lines and lines > 0
    else:
        result["bvh"] = None
        ok = False
    # Every raw file replays to the end.
    raws = sorted(os.path.join(f"{tmp}/record", n) for n in os.listdir(f"{tmp}/record") if n.endswith(".mocapraw"))
    bad = []
    for path in raws:
        r = subprocess.run([bins["mocapd"], "--replay", path], capture_output=True, text=True, timeout=600)
        if r.returncode != 0:
            bad.append({"file": os.path.basename(path), "error": (r.stdout + r.stderr)[-400:]})
    result["raw_files"], result["raw_files_bad"] = len(raws), bad
    ok &= len(raws) > 0 and not bad
    ok &= result["mocapd_exit"] == 0
    result["ok"] = bool(ok)

    refused = {}
    if result.get("stats"):
        pat = re.compile(r"(rate_limited|evict|refused|rejected|timeouts|malformed|garbage|oversized|bad_)")
        refused = {k: v for k, v in sorted(result["stats"]["counters"].items()) if pat.search(k) and v}
    result["refused"] = refused
    if a.json:
        with open(a.json, "w") as f:
            json.dump(result, f, indent=1)
    md = render_md(result)
    if a.md:
        with open(a.md, "w") as f:
            f.write(md)
    print(md)
    if not a.keep and ok:
        subprocess.run(["rm", "-rf", tmp])
    return 0 if ok else 1


def render_md(r):
    s = r["samples"]
    lines = [f"Soak: {r['duration_s']:.0f} s, {r['clients']} clients, result {'ok' if r['ok'] else 'FAILED'}", "",
             "| t (s) | RSS (MB) | fds | threads | mocapd CPU (% of a core) | load avg |",
             "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in s:
        lines.append(f"| {row['t_s']} | {row['rss_mb']} | {row['fds']} | {row['threads']} | {row['cpu_pct']} | "
                     f"{row['loadavg']} |")
    ld = r.get("load", {})
    lines += ["", f"- legitimate clients: frames lost {r['frames_lost_by_clients']} "
              f"(load client: {json.dumps({k: ld[k] for k in sorted(ld) if not isinstance(ld[k], (dict, list))})})",
              f"- BVH recording: {r['bvh']}; stop reply: {r.get('record_stop')}",
              f"- raw files: {r['raw_files']}, not replayable: {len(r['raw_files_bad'])}",
              f"- hostile side: {json.dumps(r.get('hostile', {}), sort_keys=True)}",
              f"- refused by mocapd (Stats): {json.dumps(r['refused'])}",
              f"- mocapd exit status: {r['mocapd_exit']}", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
