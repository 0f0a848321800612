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
    exports    BVH and CSV downloads of a recorded take without a token: held by slow readers
               (a 4 KiB receive window, 1 KiB read a second) from one address and from four
               (127.0.0.2-5), closed mid-stream after --export-hold-s; requests past the
               export memory budget (set small here: 1 MiB per address, 2 MiB in all), which
               must be refused with 507; requests sent and abandoned at once
    calibration  (with nats-server) mocapd runs clustered on a loopback nats-server -js that
               lets anyone in (allow_anonymous, a calibration key file); an anonymous client
               puts forged values into the calibration bucket ($KV.mocap_calibration.soak.<id>):
               unsigned, signed with another key, signed with the site's key but upside down,
               and for subjects the host does not serve. None may be applied: the host's
               refusal counter (calibration_kv.refused) must count every one, it must take
               none (calibration_kv.received), and no calibration file may change or appear.
               At the end one value signed with the site's key, upright, for a served subject
               is put the same way and must be taken: the forged ones reached the host.

Legitimate work also holds two takes: "source" (recorded first, the exports' victim) and
"live", recorded the whole time beside the exports; it must stop with ok and 0 samples lost
(judged by the real run), and a real download of the source take must succeed at the end.

Every --sample-s seconds: the daemon's VmRSS, open file descriptors, threads and CPU.
At the end: frames the legitimate clients lost (gaps + queue drops) and their latency
percentiles, the BVH recording's frame count against its MOTION lines, that every raw file
replays (mocapd --replay), the daemon's counters of what it refused, and its exit status.

Usage (Release build):
    tests/bench/soak.py --bin build [--duration-s 1800] [--md soak.md] [--json soak.json]
    tests/bench/soak.py --bin build --smoke      # 30 s, 10 clients: checks the tool itself
Exit status: 0 when every file is valid, mocapd exited 0, the export attacks met 507 and
the forged calibrations were all refused and none applied; the real run also needs no
legitimate frame lost, honest clients' p99 latency within --max-p99-ms, and the live take
stopped with 0 samples lost (frames, latency and take samples are not judged by --smoke,
which runs on any machine, under the sanitizers too).
Only python3's standard library and the repository's Python client (for the protobuf
messages) are used.
"""

import argparse
import hashlib
import hmac
import http.client
import json
import os
import random
import re
import shutil
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
SITE = "soak"
SITE_KEY = "soak-site-calibration-key-0123456789abcdef"
OTHER_KEY = "not-the-site-key-0123456789abcdef-0123456789"
FORGED_MARK = "# forged by soak.py"
HONEST_SUBJECT = 3  # served (max_subjects = 4), not streamed by the simulator
EXPORT_ADDRESSES = ["127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"]


def cluster_section(nats_port, tmp):
    if not nats_port:
        return ""
    return f"""[cluster]
nats_url = "nats://127.0.0.1:{nats_port}"
site = "{SITE}"
host_id = "soak-host"
allow_anonymous = true
calibration_key_file = "{tmp}/calibration.key"
"""


def config(ports, tmp, rotate_s, nats_port=0):
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
# Small on purpose: the export attackers must reach the budget and meet 507. An export is
# charged what it writes (a BVH ~0.15x, a CSV ~0.19x of the take's raw file: 0.3 MB each of
# the 1.5 MB source take), so four held from one address pass 1 MiB and eight held pass 2.
export_memory_mb = 2
export_memory_per_address_mb = 1
[http]
listen = "127.0.0.1:{ports['http']}"
""" + cluster_section(nats_port, tmp)


# --------------------------------------------------------------------------------------
# The hostile mix
# --------------------------------------------------------------------------------------

class Hostile:
    """Threads that attack until stop is set; `counts` says what each managed to do."""

    def __init__(self, ports, stop, scale, export_take="", export_hold_s=15.0, nats_port=0):
        self.ports, self.stop, self.scale = ports, stop, scale
        self.export_take, self.export_hold_s, self.nats_port = export_take, export_hold_s, nats_port
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
        if self.export_take:
            kinds += [(self.export_slow, 4 * s), (self.export_spread, 4 * s), (self.export_abandon, 1)]
        if self.nats_port:
            kinds += [(self.calibration, 1)]
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


    # ---- exports: downloads of a take, held, abandoned, past the budget ----

    def export_request(self, fmt):
        return (f"GET /api/takes/{self.export_take}/download?format={fmt} HTTP/1.1\r\n"
                f"Host: 127.0.0.1:{self.ports['http']}\r\n\r\n").encode()

    def export_held(self, fmt, source):
        """One download from `source`, read 1 KiB a second through a 4 KiB window, closed
        mid-stream after export_hold_s (or when stop is set)."""
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.bind((source, 0))
            s.settimeout(10)
            s.connect(("127.0.0.1", self.ports["http"]))
            s.sendall(self.export_request(fmt))
            s.settimeout(1)
            head = b""
            reply_by = time.monotonic() + 120  # the export queue may keep it a while on a loaded machine
            while b"\r\n\r\n" not in head:
                if self.stop.is_set():
                    return
                try:
                    chunk = s.recv(1024)
                except socket.timeout:
                    if time.monotonic() > reply_by:
                        raise OSError("no reply in 120 s")
                    continue
                if not chunk:
                    raise OSError("closed before the headers")
                head += chunk
            status = head.split(b" ", 2)[1].decode(errors="replace")
            self.count(f"export_status_{status}")
            if status != "200":
                return
            headers, body = head.split(b"\r\n\r\n", 1)
            m = re.search(rb"(?i)\r\ncontent-length:\s*(\d+)", headers)
            left = int(m.group(1)) - len(body) if m else None
            s.settimeout(5)
            until = time.monotonic() + self.export_hold_s
            while not self.stop.is_set() and time.monotonic() < until:
                if left is not None and left <= 0:
                    self.count("export_read_to_the_end")
                    return
                if self.stop.wait(1.0):
                    break
                try:
                    chunk = s.recv(1024)
                except socket.timeout:
                    continue
                if chunk == b"":
                    self.count("export_closed_by_daemon")
                    return
                if left is not None:
                    left -= len(chunk)
            self.count("export_closed_mid_stream")
        finally:
            s.close()

    def export_slow(self, i):
        self.export_held(("bvh", "csv")[i % 2], "127.0.0.1")

    def export_spread(self, i):
        self.export_held(("csv", "bvh")[i % 2], EXPORT_ADDRESSES[i % len(EXPORT_ADDRESSES)])

    def export_abandon(self, i):
        while not self.stop.is_set():
            with self.connect(self.ports["http"]) as s:
                s.sendall(self.export_request(("bvh", "csv")[self.counts.get("export_abandoned", 0) % 2]))
                self.count("export_abandoned")
            self.stop.wait(0.5)

    # ---- calibration: forged values put into the bucket by an anonymous NATS client ----

    def forged_values(self, k):
        """The k-th forged (subject, value): each kind in turn, each with a new time."""
        kind = k % 4
        upright, upside_down = "1.0, 0.0, 0.0, 0.0", "0.0, 1.0, 0.0, 0.0"
        if kind == 0:  # unsigned
            return "unsigned", 1 + k % 2, calibration_value(1 + k % 2, upright, "")
        if kind == 1:  # signed with a key that is not the site's
            return "other_key", 1 + k % 2, calibration_value(1 + k % 2, upright, OTHER_KEY)
        if kind == 2:  # the site's key (a broken host), the body upside down
            return "implausible", 1 + k % 2, calibration_value(1 + k % 2, upside_down, SITE_KEY)
        subject = 1000 + k  # the site's key, upright, a subject nobody configured
        return "unserved_subject", subject, calibration_value(subject, upright, SITE_KEY)

    def calibration(self, i):
        with NatsConnection(self.nats_port) as (s, f):
            k = self.counts.get("calibration_forged", 0)
            while not self.stop.is_set():
                kind, subject, value = self.forged_values(k)
                nats_put(s, f, subject, value)
                self.count("calibration_forged")
                self.count("calibration_forged_" + kind)
                k += 1
                self.stop.wait(0.25)


class NatsConnection:
    """An anonymous NATS connection: (socket, its reader) once the server answered a PING."""

    def __init__(self, port):
        self.s = socket.create_connection(("127.0.0.1", port), timeout=10)

    def __enter__(self):
        f = self.s.makefile("rb")
        if not f.readline().startswith(b"INFO"):
            raise OSError("no INFO from nats-server")
        self.s.sendall(b'CONNECT {"verbose":false,"pedantic":false,"name":"soak"}\r\nPING\r\n')
        nats_wait_pong(self.s, f)
        return self.s, f

    def __exit__(self, *exc):
        self.s.close()


def nats_put(s, f, subject, value):
    """Puts `value` under the bucket key of `subject` (a KV put is a publish to its subject)
    and returns once the server has it."""
    data = value.encode()
    s.sendall(f"PUB $KV.mocap_calibration.{SITE}.{subject} {len(data)}\r\n".encode() + data + b"\r\nPING\r\n")
    nats_wait_pong(s, f)


def nats_wait_pong(s, f):
    """Reads the NATS server's lines until PONG, answering its PINGs; raises on -ERR."""
    while True:
        line = f.readline()
        if not line:
            raise OSError("nats-server closed the connection")
        if line.startswith(b"PONG"):
            return
        if line.startswith(b"PING"):
            s.sendall(b"PONG\r\n")
        elif line.startswith(b"-ERR"):
            raise OSError(line.decode(errors="replace").strip())


def calibration_text(q_world_earth, mark=FORGED_MARK):
    """A calibration file's text for the default body model (as
    tests/integration/calibration_security_test.cpp makes them), marked by a comment."""
    return (f"{mark}\nformat = \"mocapd-calibration\"\nversion = 1\npose = \"t-pose\"\nheading = \"earth\"\n"
            f"facing_heading_rad = 0.0\nq_world_earth = [{q_world_earth}]\n[q_sensor_segment]\n"
            "pelvis = [1.0, 0.0, 0.0, 0.0]\n")


def calibration_value(subject, q_world_earth, key, host_id="soak-forger", mark=FORGED_MARK):
    """A bucket value as server/cluster/calibration_bucket.cpp writes it, signed with `key`
    ("" unsigned) as server/cluster/calibration_trust.cpp signs it."""
    text = calibration_text(q_world_earth, mark)
    time_us = time.time_ns() // 1000
    v = {"format": "mocap-calibration", "version": 1, "site": SITE, "subject": subject, "host_id": host_id,
         "time_us": time_us, "calibration": text}
    if key:
        message = f"mocap-calibration/1\n{SITE}\n{subject}\n{host_id}\n{time_us}\n{text}"
        v["hmac_sha256"] = hmac.new(key.encode(), message.encode(), hashlib.sha256).hexdigest()
    return json.dumps(v)


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


def http_call(port, method, path, timeout=60):
    """(status, body) of one request to the web endpoint, with the control token."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout)
    try:
        c.request(method, path, headers={"X-Mocap-Token": TOKEN})
        r = c.getresponse()
        return r.status, r.read()
    finally:
        c.close()


def take_raw_bytes(tmp, name):
    d = f"{tmp}/record/takes/{name}"
    try:
        return sum(os.path.getsize(os.path.join(d, n)) for n in os.listdir(d) if n.endswith(".mocapraw"))
    except OSError:
        return 0


def wait_until(pred, limit_s, step_s=0.5):
    """Polls pred until it holds or limit_s passed: events, with generous deadlines."""
    until = time.monotonic() + limit_s
    while True:
        if pred():
            return True
        if time.monotonic() >= until:
            return False
        time.sleep(step_s)


def start_nats(tmp, nats_bin):
    """nats-server with JetStream on a free loopback port, anyone let in; (process, port)."""
    port = load_run.free_port()
    log = open(f"{tmp}/nats.log", "w")
    p = subprocess.Popen([nats_bin, "-a", "127.0.0.1", "-p", str(port), "-js", "-sd", f"{tmp}/js"], stdout=log,
                         stderr=subprocess.STDOUT, preexec_fn=load_run.child_setup)
    log.close()
    if not load_run.wait_for_port(port, 30):
        load_run.stop(p, 5)
        raise SystemExit(f"soak: nats-server did not open port {port}; see {tmp}/nats.log")
    return p, port


def calibration_files(tmp):
    """{file: text} of the calibration directory."""
    d = f"{tmp}/calibration"
    out = {}
    for n in sorted(os.listdir(d)):
        try:
            with open(os.path.join(d, n), errors="replace") as f:
                out[n] = f.read()
        except OSError:
            pass
    return out


THROTTLED = "too many failed control attempts"


def file_hashes(tmp):
    return {n: hashlib.sha256(t.encode()).hexdigest()[:16] for n, t in calibration_files(tmp).items()}


def own_calibrations(client_bin, pose_port):
    """Calibrations the host made itself (a new T-pose, a refinement): they may rewrite a file."""
    st = load_run.stats(client_bin, pose_port)
    return sum(load_run.counter_sum(st, n) or 0 for n in ("calibrations_ok", "calibrations_refined"))


def control(client_bin, pose_port, *args):
    """A control request with the right token. Retried for up to 60 s while the wrong-token
    attacker has emptied the global attempt limiter (docs/security.md, "Guessing the token":
    control works again within 10 s once the failures stop)."""
    until = time.monotonic() + 60
    while True:
        r = subprocess.run([client_bin, "--connect", f"127.0.0.1:{pose_port}", "control", "--token", TOKEN, *args],
                           capture_output=True, text=True, timeout=30)
        text = (r.stdout + r.stderr).strip()
        if THROTTLED not in text or time.monotonic() >= until:
            return r.returncode, text
        time.sleep(1.0)


def http_control(port, path):
    """(status, body) of a control POST, retried as control() is."""
    until = time.monotonic() + 60
    while True:
        status, body = http_call(port, "POST", path)
        if THROTTLED.encode() not in body or time.monotonic() >= until:
            return status, body
        time.sleep(1.0)


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
    ap.add_argument("--export-hold-s", type=float, default=30.0, help="how long a slow reader holds a download")
    ap.add_argument("--source-take-mb", type=float, default=1.5,
                    help="raw size of the take the exports download, MB (each export is charged what it writes)")
    ap.add_argument("--max-p99-ms", type=float, default=50.0, help="honest clients' p99 latency bound (real run)")
    ap.add_argument("--nats-server", default="", help="path of nats-server (default: from PATH, /usr/sbin)")
    ap.add_argument("--no-cluster", action="store_true", help="no nats-server: no calibration attacks")
    ap.add_argument("--md", default="")
    ap.add_argument("--json", default="")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory (logs, recordings)")
    ap.add_argument("--smoke", action="store_true", help="20 s, 10 clients, sample every 5 s, rotate every 10 s")
    a = ap.parse_args()
    if a.smoke:
        a.duration_s, a.clients, a.sample_s, a.rotate_s, a.hostile_scale = 30.0, 10, 5.0, 10.0, 1
        a.export_hold_s = 10.0
    given = {"mocapd": a.mocapd, "mocap-sim": a.sim, "mocap-client": a.client}
    bins = {n: given[n] or load_run.find_binary(a.bin, n) for n in given}
    load_run.raise_nofile()

    tmp = tempfile.mkdtemp(prefix="soak_")
    os.makedirs(f"{tmp}/calibration")
    os.makedirs(f"{tmp}/record")
    result = {"duration_s": a.duration_s, "clients": a.clients, "tmp": tmp, "samples": []}
    nats, nats_port = None, 0
    nats_bin = a.nats_server or shutil.which("nats-server") or (
        "/usr/sbin/nats-server" if os.access("/usr/sbin/nats-server", os.X_OK) else "")
    if a.no_cluster or not nats_bin:
        # Said in the result and the report: the calibration attacks did not run.
        result["calibration"] = {"skipped": "--no-cluster" if a.no_cluster else "no nats-server binary"}
    else:
        nats, nats_port = start_nats(tmp, nats_bin)
        with open(f"{tmp}/calibration.key", "w") as f:
            f.write(SITE_KEY + "\n")
        os.chmod(f"{tmp}/calibration.key", 0o600)
    ports = {k: load_run.free_port() for k in ("sink", "pose", "bvh", "http")}
    cfg = f"{tmp}/mocapd.toml"
    with open(cfg, "w") as f:
        f.write(config(ports, tmp, a.rotate_s, nats_port))
    log = open(f"{tmp}/mocapd.log", "w")
    daemon = subprocess.Popen([bins["mocapd"], "--config", cfg], stdout=log, stderr=subprocess.STDOUT,
                              preexec_fn=load_run.child_setup)
    ok = True
    stop = threading.Event()
    hostile = Hostile(ports, stop, a.hostile_scale, "source", a.export_hold_s, nats_port)

    def daemon_log():
        log.flush()
        with open(f"{tmp}/mocapd.log", errors="replace") as f:
            return f.read()

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
        # The take the exports download: recorded first, to --source-take-mb of raw samples.
        status, body = http_call(ports["http"], "POST", "/api/takes/start?name=source")
        if status != 200:
            raise SystemExit(f"soak: take 'source' did not start: {status} {body[:300]}")
        if not wait_until(lambda: take_raw_bytes(tmp, "source") >= a.source_take_mb * 1e6, 300):
            raise SystemExit(f"soak: take 'source' holds {take_raw_bytes(tmp, 'source')} bytes after 300 s")
        status, body = http_call(ports["http"], "POST", "/api/takes/stop")
        result["source_take_stop"] = json.loads(body)
        if status != 200 or not result["source_take_stop"].get("ok"):
            raise SystemExit(f"soak: take 'source' did not stop ok: {status} {body[:300]}")
        result["source_take_bytes"] = take_raw_bytes(tmp, "source")
        # The take recorded beside the exports the whole time: it must lose nothing.
        status, body = http_call(ports["http"], "POST", "/api/takes/start?name=live")
        if status != 200:
            raise SystemExit(f"soak: take 'live' did not start: {status} {body[:300]}")
        if nats_port:
            # The calibration attacks start once the host watches the bucket.
            if not wait_until(lambda: "calibrations shared through the JetStream bucket" in daemon_log(), 120):
                raise SystemExit("soak: mocapd did not open the calibration bucket in 120 s; its log:\n" +
                                 daemon_log()[-2000:])
            # The simulated subjects calibrate themselves from their opening T-pose: their files
            # are there before the snapshot, as a rule (if not, the counters below tell).
            wait_until(lambda: len(calibration_files(tmp)) >= 2, 60)
            result["calibration_files_before"] = file_hashes(tmp)
            result["own_calibrations_before"] = own_calibrations(bins["mocap-client"], ports["pose"])
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
        status, body = http_control(ports["http"], "/api/takes/stop")
        result["live_take_stop"] = json.loads(body) if body.strip().startswith(b"{") else {"status": status}
        status, body = http_call(ports["http"], "GET", "/api/takes/live")
        result["live_take"] = ({k: v for k, v in json.loads(body).items() if k in ("samples", "samples_lost", "loss")}
                               if status == 200 else {"status": status})
        # A real download once the attackers are gone: their budget is given back. Retried on
        # 507 while the daemon notices the last closed connections.
        got = []

        def honest_download():
            got[:] = [http_call(ports["http"], "GET", "/api/takes/source/download?format=bvh", timeout=300)]
            return got[0][0] != 507

        wait_until(honest_download, 60, 2.0)
        result["honest_download"] = {"status": got[0][0], "bytes": len(got[0][1]),
                                     "bvh": got[0][1].startswith(b"HIERARCHY")}
        sim_out, _ = sim.communicate(timeout=60)
        result["sim"] = sim_out.strip().splitlines()[-1] if sim_out.strip() else ""
        if nats_port:
            # Every forged value reaches the host and is refused: the counter catches up.
            forged = hostile.counts.get("calibration_forged", 0)
            wait_until(lambda: (load_run.counter_sum(load_run.stats(bins["mocap-client"], ports["pose"]),
                                                     "calibration_kv.refused") or 0) >= forged, 120, 1.0)
            result["calibration_received_before_control"] = load_run.counter_sum(
                load_run.stats(bins["mocap-client"], ports["pose"]), "calibration_kv.received")
            # The control: one value as a host holding the site's key makes it, upright, for a
            # served subject, through the same path as the forged ones. It must be taken: the
            # forged values reached the host and were refused for what they are, not lost.
            with NatsConnection(nats_port) as (s, f):
                nats_put(s, f, HONEST_SUBJECT, calibration_value(HONEST_SUBJECT, "1.0, 0.0, 0.0, 0.0", SITE_KEY,
                                                                 "soak-peer", "# the control value of soak.py"))
            wait_until(lambda: f"calibration-subject-{HONEST_SUBJECT}.toml" in calibration_files(tmp), 120, 1.0)
            result["own_calibrations_after"] = own_calibrations(bins["mocap-client"], ports["pose"])
        result["stats"] = load_run.stats(bins["mocap-client"], ports["pose"])
    finally:
        stop.set()
        result["mocapd_exit"] = load_run.stop(daemon, 20)
        log.close()
        if nats:
            load_run.stop(nats, 10)

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
    # client may fall behind: frames lost, latency and take samples lost are reported there,
    # and judged in the real run.
    live = result.get("live_take", {})
    if not a.smoke:
        ok &= lost == 0 and ld.get("closed_early") == 0
        ok &= ld.get("p99_ms") is not None and ld["p99_ms"] <= a.max_p99_ms
        ok &= result.get("live_take_stop", {}).get("ok") is True and live.get("samples_lost") == 0
    ok &= live.get("samples", 0) > 0
    # Exports: the attackers met the budget (507, counted), nothing else broke, and a real
    # download succeeds once they are gone.
    counters = (result.get("stats") or {}).get("counters", {})
    h = result.get("hostile", {})
    result["exports"] = {"held_200": h.get("export_status_200", 0), "refused_507": h.get("export_status_507", 0),
                         "other_status": {k: v for k, v in h.items() if k.startswith("export_status_")
                                          and k not in ("export_status_200", "export_status_507")},
                         "closed_mid_stream": h.get("export_closed_mid_stream", 0),
                         "abandoned": h.get("export_abandoned", 0),
                         "over_budget_counter": load_run.counter_sum(result.get("stats"), "take_exports_over_budget"),
                         "honest_download": result.get("honest_download")}
    ex = result["exports"]
    ok &= ex["held_200"] > 0 and ex["refused_507"] > 0 and (ex["over_budget_counter"] or 0) >= ex["refused_507"]
    ok &= (ex["honest_download"] or {}).get("status") == 200 and ex["honest_download"]["bvh"]
    # Calibration: every forged value refused, none taken, none in a file.
    if nats_port:
        forged = h.get("calibration_forged", 0)
        before, after = result.get("calibration_files_before") or {}, file_hashes(tmp)
        control_file = f"calibration-subject-{HONEST_SUBJECT}.toml"
        own_moved = result.get("own_calibrations_after") != result.get("own_calibrations_before")
        cal = {"forged": forged,
               "forged_by_kind": {k[len("calibration_forged_"):]: v for k, v in sorted(h.items())
                                  if k.startswith("calibration_forged_")},
               "refused_counter": counters.get("calibration_kv.refused"),
               "received_before_control": result.get("calibration_received_before_control"),
               "received_counter": counters.get("calibration_kv.received"),
               "control_value_taken": control_file in after and control_file not in before,
               "files_before": before, "files_after": after,
               "files_changed": [n for n in before if after.get(n) != before[n]],
               "files_new": sorted(set(after) - set(before) - {control_file}),
               "host_calibrated_meanwhile": own_moved}
        result["calibration"] = cal
        ok &= forged > 0 and (cal["refused_counter"] or 0) >= forged and cal["received_before_control"] == 0
        ok &= cal["control_value_taken"] and cal["received_counter"] == 1
        # A forged value applied would rewrite its subject's file or add one; the host's own
        # calibrations (counted) may rewrite a file, and then the counters say so.
        ok &= not [n for n in cal["files_new"] if not re.fullmatch(r"calibration-subject-[1-4]\.toml", n)]
        ok &= (not cal["files_new"] and not cal["files_changed"]) or own_moved
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
        pat = re.compile(r"(rate_limited|evict|refused|rejected|timeouts|malformed|garbage|oversized|bad_|"
                         r"over_budget|abandoned)")
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
              f"- take 'live' (beside the exports): {json.dumps(r.get('live_take'))}; stop reply: "
              f"{json.dumps(r.get('live_take_stop'))}",
              f"- exports of take 'source' ({r.get('source_take_bytes')} bytes of raw samples): "
              f"{json.dumps(r.get('exports'))}",
              f"- calibration attacks: {json.dumps(r.get('calibration'))}",
              f"- raw files: {r['raw_files']}, not replayable: {len(r['raw_files_bad'])}",
              f"- hostile side: {json.dumps(r.get('hostile', {}), sort_keys=True)}",
              f"- refused by mocapd (Stats): {json.dumps(r['refused'])}",
              f"- mocapd exit status: {r['mocapd_exit']}", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
