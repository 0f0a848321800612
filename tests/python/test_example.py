"""examples/record_angles.py against the calibrated simulated walk: a PNG with the plot
and a CSV whose angles follow the walk (knees bend, left and right in opposite phase)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[2] / "clients" / "python" / "examples" / "record_angles.py"


def run_example(walk, tmp_path, *extra):
    out, table = tmp_path / "angles.png", tmp_path / "angles.csv"
    r = subprocess.run([sys.executable, str(EXAMPLE), "--connect", walk.daemon.endpoint, "--subject", "1",
                        "--duration", "2", "--out", str(out), "--csv", str(table), *extra],
                       capture_output=True, text=True, timeout=60)
    return r, out, table


def test_example_plots_knee_and_elbow_flexion(walk, tmp_path):
    assert EXAMPLE.is_file(), EXAMPLE
    r, out, table = run_example(walk, tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "not calibrated" not in r.stderr

    data = np.loadtxt(table, delimiter=",", skiprows=1)
    t, lk, rk, le, re = data.T
    assert 150 <= len(t) <= 210 and 1.8 < t[-1] < 2.1, "2 s of frames at 100 Hz"
    # The simulated walk: knee flexion 5..65 deg, elbow 10..30 deg, sides half a stride apart.
    assert np.ptp(lk) > 30 and np.ptp(rk) > 30
    assert np.ptp(le) > 8 and np.ptp(re) > 8
    assert -20 < lk.min() and lk.max() < 90
    assert np.corrcoef(lk, rk)[0, 1] < -0.5

    import matplotlib.image as mpimg
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = mpimg.imread(out)
    assert img.shape[0] > 300 and img.shape[1] > 500
    rgb = img[..., :3]
    # Lines in the two colours cover a real share of the image (tab:blue, tab:orange).
    blue = np.all(np.abs(rgb - np.array([0.12, 0.47, 0.71])) < 0.1, axis=-1).sum()
    orange = np.all(np.abs(rgb - np.array([1.0, 0.50, 0.05])) < 0.1, axis=-1).sum()
    assert blue > 1000 and orange > 1000, (blue, orange)


def test_example_reports_a_refused_calibration(walk, tmp_path):
    r, out, _ = run_example(walk, tmp_path, "--calibrate", "--token", "wrong", "--settle-s", "0.2")
    assert r.returncode == 1 and "bad token" in r.stderr, r.stdout + r.stderr
    assert not out.exists()


def test_example_reports_an_unreachable_daemon(tmp_path):
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: connect is refused
        r = subprocess.run([sys.executable, str(EXAMPLE), "--connect", f"127.0.0.1:{port}", "--out",
                            str(tmp_path / "x.png")], capture_output=True, text=True, timeout=30)
    assert r.returncode == 2 and "cannot connect" in r.stderr
