"""Fixtures: the real mocapd on loopback with a generated config, fed by mocap-sim stream.

The binaries come from the environment (ctest sets them): MOCAPD_BIN, MOCAP_SIM_BIN.
Every port the daemon listens on is a free one, so parallel ctest runs never collide.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

import mocapd_client as mc

TOKEN = "py-s3cret-0123456789"
RATE_HZ = 100
CALIBRATE_S = 4.0  # still T-pose at the start of the simulated walk
BLEND_S = 1.0  # the walk blends in over this long after the T-pose (clients/sim/stream_motion)


def binary(env: str) -> str:
    path = os.environ.get(env)
    if not path or not os.access(path, os.X_OK):
        pytest.fail(f"{env} must name the built executable (ctest sets it)")
    return path


_HANDED_OUT: set[int] = set()


def free_port() -> int:
    """A port the kernel just handed out, never one already returned in this process (the
    kernel may hand the same free port out twice in a row)."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port


def wait_for_port(port: int, limit_s: float, process: subprocess.Popen) -> bool:
    end = time.monotonic() + limit_s
    while time.monotonic() < end and process.poll() is None:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.02)
    return False


def stop(process: subprocess.Popen, grace_s: float = 10.0) -> int:
    if process.poll() is None:
        process.terminate()
        try:
            return process.wait(grace_s)
        except subprocess.TimeoutExpired:
            process.kill()
    return process.wait()


@dataclass
class Daemon:
    process: subprocess.Popen
    dir: Path
    sink_port: int
    pose_port: int

    @property
    def endpoint(self) -> str:
        return f"127.0.0.1:{self.pose_port}"

    def log(self) -> str:
        return (self.dir / "mocapd.log").read_text(errors="replace")

    def client(self) -> mc.Client:
        c = mc.Client("127.0.0.1", self.pose_port, timeout=5.0)
        c.connect()
        return c


# The config compiled into mocapd: every "...listen" key in it is a port the daemon opens.
SHIPPED_CONFIG = Path(__file__).resolve().parents[2] / "config" / "mocapd.toml"


def daemon_config(work: Path, sink_port: int, pose_port: int) -> str:
    """The daemon's config: loopback only, and a free port for every listening key the
    shipped config has (live BVH, HTTP, and whatever comes later), so parallel runs never
    collide on a default port."""
    sections: dict[str, dict] = {
        "log": {"level": "info", "stats_interval_s": 0},
        "ingest": {"sink_listen": f"127.0.0.1:{sink_port}"},
        "pipeline": {"workers": 2, "max_subjects": 4},
        "skeleton": {"calibration_dir": str(work)},
        "serve": {"pose_listen": f"127.0.0.1:{pose_port}"},
        "control": {"token": TOKEN},
        "outputs": {"record_dir": str(work)},
    }
    with open(SHIPPED_CONFIG, "rb") as fh:
        shipped = tomllib.load(fh)
    for name, table in shipped.items():
        for key, value in table.items() if isinstance(table, dict) else ():
            if key.endswith("listen") and isinstance(value, str):
                sections.setdefault(name, {}).setdefault(key, f"127.0.0.1:{free_port()}")
    lines = []
    for name, table in sections.items():
        lines.append(f"[{name}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in table.items()]  # JSON scalars are TOML
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="session")
def daemon(tmp_path_factory):
    work = tmp_path_factory.mktemp("mocapd")
    sink_port, pose_port = free_port(), free_port()
    config = work / "mocapd.toml"
    config.write_text(daemon_config(work, sink_port, pose_port))
    with open(work / "mocapd.log", "wb") as log:
        process = subprocess.Popen([binary("MOCAPD_BIN"), "--config", str(config)], cwd=work, stdout=log,
                                   stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    d = Daemon(process, work, sink_port, pose_port)
    try:
        if not (wait_for_port(pose_port, 10, process) and wait_for_port(sink_port, 10, process)):
            pytest.fail("mocapd did not listen:\n" + d.log())
        yield d
    finally:
        rc = stop(process)
    assert rc == 0, "mocapd must drain and exit 0 on SIGTERM:\n" + d.log()


@dataclass
class Walk:
    """A simulated subject 1 (15 nodes) walking after a still T-pose, calibrated."""

    daemon: Daemon
    sim: subprocess.Popen


def wait_frames(c: mc.Client, until, limit_s: float) -> mc.Frame:
    end = time.monotonic() + limit_s
    for f in c.frames(idle_timeout=5.0):
        if until(f):
            return f
        if time.monotonic() > end:
            break
    pytest.fail("the awaited frame did not come")


@pytest.fixture(scope="session")
def walk(daemon):
    """Starts the simulated walk, calibrates it in its T-pose with the control token, and
    returns once the subject walks at full stride."""
    with open(daemon.dir / "sim.log", "wb") as log:
        sim = subprocess.Popen(
            [binary("MOCAP_SIM_BIN"), "stream", "--connect", f"127.0.0.1:{daemon.sink_port}", "--rate",
             str(RATE_HZ), "--subjects", "1", "--nodes", "15", "--duration", "600", "--calibrate-s",
             str(CALIBRATE_S), "--seed", "11"], stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    try:
        with daemon.client() as c:
            c.subscribe(subjects=[1])
            first = wait_frames(c, lambda f: True, 10)
            # One second of frames lets the filters settle; the T-pose lasts CALIBRATE_S.
            wait_frames(c, lambda f: f.sync >= first.sync + RATE_HZ, 5)
            reply = c.control(TOKEN, calibrate=1, pose="T")
            assert reply.ok, reply.error
            wait_frames(c, lambda f: f.all_flagged(mc.SegmentFlags.CALIBRATED), 10)
            walking = first.sync + int((CALIBRATE_S + BLEND_S + 0.5) * RATE_HZ)
            wait_frames(c, lambda f: f.sync >= walking, 15)
        yield Walk(daemon, sim)
    finally:
        stop(sim)
