"""The VMC output (docs/outputs.md, "VMC") received by receivers nobody here wrote: the real
mocapd, fed by mocap-sim stream and calibrated in the simulated T-pose, sends subject 1 to
python3-liblo and to liblo's oscdump at once. Checked: the addresses, names and message count
of every bundle, one bundle per pose frame, /VMC/Ext/T stepping with the sample period, and
that composing the received local rotations down Unity's humanoid hierarchy (bones not sent
are the identity) gives back the pose service's world orientations of the same frames,
converted to Unity's frame, within 0.1 degree.

Fixtures and helpers come from tests/python/conftest.py (ctest puts it on PYTHONPATH).
"""

from __future__ import annotations

import subprocess
import threading
import time

import liblo
import numpy as np
import pytest

import mocapd_client as mc
from conftest import CALIBRATE_S, RATE_HZ, TOKEN, binary, daemon_config, free_port, stop, wait_for_port

# The default body's bones in segment order, and each one's parent among Unity's humanoid
# bones (HumanTrait), written out here independently of server/serve/vmc_rig.cpp.
BONES = ["Hips", "Spine", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand", "RightUpperArm", "RightLowerArm",
         "RightHand", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]
UNITY_PARENT = {
    "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest", "Neck": "UpperChest", "Head": "Neck",
    "LeftShoulder": "UpperChest", "LeftUpperArm": "LeftShoulder", "LeftLowerArm": "LeftUpperArm",
    "LeftHand": "LeftLowerArm", "RightShoulder": "UpperChest", "RightUpperArm": "RightShoulder",
    "RightLowerArm": "RightUpperArm", "RightHand": "RightLowerArm", "LeftUpperLeg": "Hips",
    "LeftLowerLeg": "LeftUpperLeg", "LeftFoot": "LeftLowerLeg", "RightUpperLeg": "Hips",
    "RightLowerLeg": "RightUpperLeg", "RightFoot": "RightLowerLeg",
}
SECONDS = 4.0  # of calibrated walking collected from both outputs
TOLERANCE_DEG = 0.1  # the bound; float32 on both wires costs ~0.001 degree


def qmul(a, b):
    """Hamilton product of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def unity_from_ours(q):
    """Our (w, x, y, z) in x forward, y left, z up -> Unity's rotation as (w, x, y, z): the
    axes turn by u = (-y, z, x), a reflection, so the vector part picks up a minus sign."""
    w, x, y, z = q
    return np.array([w, y, -z, -x])


def angle_deg(a, b):
    """Rotation angle between two quaternions: 2 atan2(|v|, |w|) of a* b, which stays exact
    near zero (2 acos|w| turns the float32 norm error of 1e-7 into 0.05 degree)."""
    d = qmul(np.array([a[0], -a[1], -a[2], -a[3]]), b)
    return np.degrees(2 * np.arctan2(np.linalg.norm(d[1:]), abs(d[0])))


class Receiver:
    """python3-liblo on a UDP port: each bundle as a list of (path, args), with its arrival time."""

    def __init__(self):
        self.server = liblo.Server(free_port(), liblo.UDP)
        self.bundles: list[tuple[float, list]] = []
        self.current: list | None = None
        self.server.add_method(None, None, self.on_message)
        self.server.add_bundle_handlers(self.on_start, self.on_end)
        self.done = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def on_start(self, timetag, user):
        self.current = []

    def on_end(self, user):
        self.bundles.append((time.monotonic(), self.current))
        self.current = None

    def on_message(self, path, args, types, src):
        if self.current is None:
            self.bundles.append((time.monotonic(), [(path, args, "loose")]))
        else:
            self.current.append((path, args))

    def run(self):
        while not self.done.is_set():
            self.server.recv(50)

    def close(self):
        self.done.set()
        self.thread.join(5)
        self.server.free()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    work = tmp_path_factory.mktemp("vmc")
    rx = Receiver()
    dump_port = free_port()
    dump_log = open(work / "oscdump.txt", "wb")
    dump = subprocess.Popen(["oscdump", "-L", str(dump_port)], stdout=dump_log, stderr=subprocess.STDOUT)
    sink_port, pose_port = free_port(), free_port()
    config = work / "mocapd.toml"
    config.write_text(daemon_config(work, sink_port, pose_port) +
                      f'[vmc]\nenabled = true\ndestinations = ["127.0.0.1:{rx.server.port}", '
                      f'"localhost:{dump_port}"]\nsubject = 1\n')
    check = subprocess.run([binary("MOCAPD_BIN"), "--check-config", str(config)], capture_output=True, text=True)
    assert check.returncode == 0, check.stderr
    log = open(work / "mocapd.log", "wb")
    daemon = subprocess.Popen([binary("MOCAPD_BIN"), "--config", str(config)], cwd=work, stdout=log,
                              stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    sim = None
    frames: list[mc.Frame] = []
    try:
        assert wait_for_port(pose_port, 20, daemon), (work / "mocapd.log").read_text()
        with mc.Client("127.0.0.1", pose_port, timeout=5.0) as c:
            c.subscribe(subjects=[1], fields=mc.Fields.ORIENTATIONS)
            sim = subprocess.Popen(
                [binary("MOCAP_SIM_BIN"), "stream", "--connect", f"127.0.0.1:{sink_port}", "--rate", str(RATE_HZ),
                 "--subjects", "1", "--nodes", "15", "--duration", "600", "--calibrate-s", str(CALIBRATE_S),
                 "--seed", "5"], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
            calibrated_at = None
            deadline = time.monotonic() + 90  # generous: a sanitizer build on a loaded host
            for f in c.frames(idle_timeout=10.0):
                frames.append(f)
                if calibrated_at is None and f.sync >= frames[0].sync + RATE_HZ:
                    reply = c.control(TOKEN, calibrate=1, pose="T")
                    assert reply.ok, reply.error
                    calibrated_at = f.sync
                if calibrated_at is not None and f.all_flagged(mc.SegmentFlags.CALIBRATED):
                    walking = [g for g in frames if g.all_flagged(mc.SegmentFlags.CALIBRATED)]
                    if walking[-1].sample_us - walking[0].sample_us >= (CALIBRATE_S + SECONDS) * 1e6:
                        break
                assert time.monotonic() < deadline, "the walk did not run long enough"
        # The last bundles are on their way; the count check below allows for them.
        wait_for = time.monotonic() + 5
        while time.monotonic() < wait_for and (not rx.bundles or rx.bundles[-1][0] > time.monotonic() - 0.5):
            time.sleep(0.1)
    finally:
        if sim is not None:
            stop(sim)
        rc = stop(daemon)
        rx.close()
        stop(dump)
        dump_log.close()
        log.close()
    assert rc == 0, (work / "mocapd.log").read_text()
    yield frames, rx.bundles, (work / "oscdump.txt").read_text(errors="replace"), (work / "mocapd.log").read_text()


def test_every_bundle_is_root_fifteen_bones_ok_and_time(session):
    _, bundles, _, _ = session
    assert len(bundles) > 2 * RATE_HZ
    for _, messages in bundles:
        paths = [m[0] for m in messages]
        assert paths == ["/VMC/Ext/Root/Pos"] + ["/VMC/Ext/Bone/Pos"] * len(BONES) + ["/VMC/Ext/OK", "/VMC/Ext/T"]
        assert messages[0][1][0] == "root" and len(messages[0][1]) == 8
        assert [m[1][0] for m in messages[1:1 + len(BONES)]] == BONES
        assert all(len(m[1]) == 8 for m in messages[1:1 + len(BONES)])
        ok = messages[-2][1]
        assert ok[0] == 1 and ok[1] in (0, 3) and ok[2] == 0 and ok[3] in (0, 1)
    assert bundles[-1][1][-2][1][1] == 3, "calibrated at the end"


def matched(frames, bundles):
    """Pairs (pose frame, bundle) of the same sample instant: /VMC/Ext/T counts seconds from the
    output's first frame, so one offset maps it to the frames' sample time. The pose client
    subscribed before the simulator started, so the offset is found among the first frames."""
    t = np.array([b[1][-1][1][0] for b in bundles], dtype=np.float64)
    s = np.array([f.sample_us for f in frames], dtype=np.float64) * 1e-6
    best, best_hits = None, -1
    for c in {round(si - ti, 6) for si in s[:20] for ti in t[:20]}:
        hits = np.count_nonzero(np.min(np.abs((s[:, None] - c) - t[None, :200]), axis=1) < 5e-5)
        if hits > best_hits:
            best, best_hits = c, hits
    pairs = []
    for f, si in zip(frames, s):
        i = int(np.argmin(np.abs(t - (si - best))))
        if abs(t[i] - (si - best)) < 5e-5:
            pairs.append((f, bundles[i][1]))
    return pairs


def test_one_bundle_per_frame_at_the_frame_rate(session):
    frames, bundles, _, _ = session
    t = np.array([b[1][-1][1][0] for b in bundles])
    assert np.all(np.diff(t) > 0), "/VMC/Ext/T only grows"
    syncs = np.array([f.sync for f in frames])
    period_s = np.median(np.diff([f.sample_us for f in frames])) * 1e-6 / np.median(np.diff(syncs))
    assert period_s == pytest.approx(1.0 / RATE_HZ, rel=0.05)
    assert np.median(np.diff(t)) == pytest.approx(period_s * np.median(np.diff(syncs)), rel=0.05)
    pairs = matched(frames, bundles)
    # Every pose frame has its bundle. UDP on loopback, the sender's 64-frame queue and a
    # Python receiver on a loaded host (or under a sanitizer) may lose a few, not more.
    assert len(pairs) >= 0.90 * len(frames), (len(pairs), len(frames), len(bundles))
    rate_hz = (len(bundles) - 1) / (bundles[-1][0] - bundles[0][0])
    print(f"VMC bundles: {len(bundles)} at {rate_hz:.1f} Hz (arrival), {len(pairs)} of {len(frames)} frames matched")


def test_composed_local_rotations_are_the_world_orientations(session):
    frames, bundles, _, _ = session
    pairs = [(f, b) for f, b in matched(frames, bundles) if f.all_flagged(mc.SegmentFlags.CALIBRATED)]
    assert len(pairs) >= RATE_HZ * SECONDS * 0.9
    worst = 0.0
    for f, messages in pairs:
        local = {}
        for path, args in messages[1:1 + len(BONES)]:
            x, y, z, w = args[4:8]
            local[args[0]] = np.array([w, x, y, z])
        rx, ry, rz, rw = messages[0][1][4:8]
        root = np.array([rw, rx, ry, rz])
        for s, bone in enumerate(BONES):
            g = local[bone]
            parent = UNITY_PARENT.get(bone)
            while parent is not None:
                if parent in local:
                    g = qmul(local[parent], g)
                parent = UNITY_PARENT.get(parent)
            g = qmul(root, g)
            worst = max(worst, angle_deg(g, unity_from_ours(f.q[s])))
    print(f"largest difference over {len(pairs)} frames x {len(BONES)} bones: {worst:.5f} deg")
    assert worst < TOLERANCE_DEG


def test_oscdump_receives_the_same_stream(session):
    _, bundles, dump, _ = session
    lines = dump.splitlines()
    assert sum("/VMC/Ext/T" in line for line in lines) >= 0.9 * len(bundles), dump[-2000:]
    assert any("/VMC/Ext/Bone/Pos sfffffff \"Hips\"" in line for line in lines), dump[:2000]
    assert any("/VMC/Ext/Root/Pos sfffffff \"root\"" in line for line in lines), dump[:2000]


def test_the_daemon_logs_where_it_sends(session):
    _, _, _, log = session
    assert "vmc: sending 15 bones of subject 1 to 127.0.0.1:" in log
    assert "segments without a humanoid bone" not in log


def test_a_destination_that_does_not_resolve_yet_is_retried_not_refused(tmp_path):
    # --check-config names the typo; start-up does not look names up (DNS may not be up at
    # boot): the daemon runs, serves, and its sender logs and retries the look-up.
    sink_port, pose_port = free_port(), free_port()
    config = tmp_path / "mocapd.toml"
    config.write_text(daemon_config(tmp_path, sink_port, pose_port) +
                      '[vmc]\nenabled = true\ndestinations = ["no-such-host.invalid:39539"]\n')
    check = subprocess.run([binary("MOCAPD_BIN"), "--check-config", str(config)], capture_output=True, text=True)
    assert check.returncode != 0
    assert 'vmc.destinations[0]: cannot resolve host "no-such-host.invalid"' in check.stderr, check.stderr
    log_path = tmp_path / "mocapd.log"
    with open(log_path, "wb") as log:
        daemon = subprocess.Popen([binary("MOCAPD_BIN"), "--config", str(config)], cwd=tmp_path, stdout=log,
                                  stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        try:
            assert wait_for_port(pose_port, 20, daemon), log_path.read_text()
            deadline = time.monotonic() + 30
            while "vmc: destination no-such-host.invalid:39539:" not in log_path.read_text():
                assert daemon.poll() is None and time.monotonic() < deadline, log_path.read_text()
                time.sleep(0.1)
            assert "retrying every" in log_path.read_text()
        finally:
            rc = stop(daemon)
    assert rc == 0, log_path.read_text()
