"""The real mocapd (the build's binary, MOCAPD_BIN) on loopback with a generated config, as
tests/python/conftest.py starts it: every port a free one, so parallel runs never collide.
Its Prometheus /metrics is how the firmware-in-the-loop tests see what it received.
"""

import json
import os
import re
import socket
import subprocess
import time
import tomllib
import urllib.request
from pathlib import Path

SHIPPED_CONFIG = Path(__file__).resolve().parents[2] / "config" / "mocapd.toml"
_HANDED_OUT = set()


def free_port():
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port


class Mocapd:
    def __init__(self, work, binary=None):
        self.work = Path(work)
        self.binary = binary or os.environ["MOCAPD_BIN"]
        self.sink_port, self.http_port = free_port(), free_port()
        sections = {
            "log": {"level": "info", "stats_interval_s": 0},
            "ingest": {"sink_listen": f"127.0.0.1:{self.sink_port}"},
            "pipeline": {"workers": 2, "max_subjects": 4},
            "skeleton": {"calibration_dir": str(self.work)},
            "serve": {"pose_listen": f"127.0.0.1:{free_port()}"},
            "control": {"token": "firmware-loop-0123456789"},
            "outputs": {"record_dir": str(self.work)},
            "http": {"enabled": True, "listen": f"127.0.0.1:{self.http_port}"},
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
            lines += [f"{k} = {json.dumps(v)}" for k, v in table.items()]
        self.config = self.work / "mocapd.toml"
        self.config.write_text("\n".join(lines) + "\n")
        self.process = None
        self.starts = 0

    @property
    def sink_address(self):
        return ("127.0.0.1", self.sink_port)

    def log(self):
        return (self.work / "mocapd.log").read_text(errors="replace")

    def start(self, limit_s=30):
        self.starts += 1
        with open(self.work / "mocapd.log", "ab") as log:
            self.process = subprocess.Popen([self.binary, "--config", str(self.config)], cwd=self.work, stdout=log,
                                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        ready = self.starts  # "mocapd ready" lines in the log, one per start
        end = time.monotonic() + limit_s
        while time.monotonic() < end and self.process.poll() is None:
            if self.log().count("mocapd ready") >= ready:
                return self
            time.sleep(0.05)
        raise RuntimeError("mocapd did not start:\n" + self.log())

    def stop(self, grace_s=20):
        """SIGTERM; returns the exit status (0 = drained and exited as it should)."""
        if self.process is None:
            return None
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(grace_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
        rc, self.process = self.process.wait(), None
        return rc

    def metrics(self):
        """{name or name{labels}: value} of /metrics."""
        with urllib.request.urlopen(f"http://127.0.0.1:{self.http_port}/metrics", timeout=10) as r:
            text = r.read().decode()
        out = {}
        for line in text.splitlines():
            m = re.match(r"^([A-Za-z_:][\w:]*(?:\{[^}]*\})?)\s+(\S+)$", line)
            if m:
                out[m.group(1)] = float(m.group(2))
        return out

    def metric(self, name):
        return self.metrics().get(name, 0.0)
