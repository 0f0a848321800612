"""Body-aware fusion on the live daemon (docs/fusion.md): the real mocapd records a simulated
subject walking on the `steel-floor` environment (tests/bench/body_fusion.py record: raw
recorder on, [fusion] heading = "auto", the simulator's --truth), and the recording is
replayed under heading = "auto" and heading = "magnetometer" (replay is deterministic and
~100x faster than live, so one live run serves both). The joint angles are compared with the
truth from SKIP_S on (T-pose, calibration, blend into the walk, the start-up of the chain).

Checked: the recording holds every instant the simulator sent; with "auto", knee flexion and
the worst joint angle stay within bounds measured on this recording plus a margin;
"magnetometer" on the same samples is worse by at least MIN_KNEE_GAIN_DEG in knee flexion, so
the test fails if the chain stage stops holding the headings (with it gone, both replays
would be the same solve).

The contrast rests on what the default filter does alone here: it loses the right calf's
heading (the simulator's gyro bias is not learned in a 2 s T-pose, and the heading guard then
refuses the field for up to a minute), which the knee hinge holds in "auto". A filter that
keeps that heading shrinks the magnetometer's knee error towards auto's (1.1° with a 6 s
T-pose): then the contrast needs a disturbance the filter cannot ride out.

The binaries come from the environment (ctest sets MOCAPD_BIN and MOCAP_SIM_BIN); the
measurement is tests/bench/body_fusion.py's, run as a command.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

TOOL = Path(__file__).resolve().parents[1] / "bench" / "body_fusion.py"
WALK_S = 45  # simulated seconds: the 2 s T-pose, a 1 s blend, then 42 s of walking (1.6 laps)
SEED = 1
# Evaluated from 15 s on: 30 s of walking. Before that the recording is the start-up: the
# T-pose (calibration at 0.5-1.5 s), the blend, and in about half of the runs the chain stage
# losing the right calf's heading for ~5 s from 7.5 s (knee flexion 48° RMS there), which
# does not come back later in the walk; body_fusion.py's table keeps it in its first minute.
SKIP_S = 15.0

# Measured on this recording (seed 1, 7 live runs, among them 4 on a host whose cores were
# busy: 0.2-41 % of the simulator's steps off its 10 ms period by more than 2 ms):
#   auto:         knee flexion 0.72-0.94°; worst angle left_hip.rotation, 40.2-40.4° in the
#                 runs without the calf episode, 61.7-63.6° with it (the pelvis's heading,
#                 which no hinge holds, drifts at 1.6-2.3°/s with its gyro bias);
#   magnetometer: knee flexion 9.7-22.4° (the default filter loses the right calf's heading).
# With the filter's vertical-bias measurement (mocap_filter.hpp; one run, idle host): auto knee
# flexion 0.72°, worst angle left_shoulder.rotation 23.7°; magnetometer knee flexion 28.3°.
# Bounds: knee flexion within the goal's 2° (+1.1° over the largest); the worst angle +6.4°
# over the largest (loose while the pelvis drifts: tighten it when that is fixed); the knee
# contrast at 5°, below the smallest measured gap (8.9°, a busy host; 12.9° otherwise).
KNEE_FLEXION_MAX_DEG = 2.0
WORST_ANGLE_MAX_DEG = 70.0
MIN_KNEE_GAIN_DEG = 5.0  # magnetometer minus auto, knee flexion


def binary(env: str) -> str:
    path = os.environ.get(env)
    if not path or not os.access(path, os.X_OK):
        pytest.fail(f"{env} must name the built executable (ctest sets it)")
    return path


def tool(*args: str, timeout_s: float) -> str:
    cmd = [sys.executable, str(TOOL), "--mocapd", binary("MOCAPD_BIN"), "--sim", binary("MOCAP_SIM_BIN"), *args]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    assert r.returncode == 0, f"{' '.join(cmd)} exited {r.returncode}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r.stdout


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("body_fusion") / "steel-floor"
    # Generous: the run itself is WALK_S of wall time; the rest is start-up and drain.
    meta = json.loads(tool("record", "--env", "steel-floor", "--duration", str(WALK_S), "--seed", str(SEED), "--out",
                           str(out), timeout_s=WALK_S + 180))
    print(f"\n[ metrics  ] recording: {meta['sim']['samples']} samples, {meta['sim']['syncs_skipped']} SYNCs skipped "
          f"by the simulator, {meta['wall_s']} s")
    return out


def evaluate(recording: Path, heading: str) -> dict:
    r = json.loads(tool("eval", str(recording), "--heading", heading, "--skip-s", str(SKIP_S), timeout_s=120))
    print(f"\n[ metrics  ] heading = {heading}: worst {r['worst_angle']} {r['max_rmse_deg']}°, knee flexion "
          f"{r['knee_flexion_rmse_deg']}°, elbow flexion {r['elbow_flexion_rmse_deg']}°, "
          f"{r['rows_evaluated']} frames over {r['evaluated_s']} s from {r['skip_s']} s; SYNC steps {r['timing']}; "
          f"{r['replay']}")
    return r


@pytest.fixture(scope="module")
def auto(recording):
    return evaluate(recording, "auto")


@pytest.fixture(scope="module")
def magnetometer(recording):
    return evaluate(recording, "magnetometer")


def test_the_recording_is_the_walk(auto):
    # Every instant the simulator sent is in the recording (a frame per SYNC, joined on sync).
    assert auto["rows_joined"] >= 0.99 * auto["rows_truth"], auto
    assert auto["evaluated_s"] >= WALK_S - SKIP_S - 1.0, auto


def test_auto_holds_the_joint_angles(auto):
    assert auto["knee_flexion_rmse_deg"] <= KNEE_FLEXION_MAX_DEG, auto["angles"]
    assert auto["max_rmse_deg"] <= WORST_ANGLE_MAX_DEG, auto["angles"]


def test_magnetometer_alone_is_worse(auto, magnetometer):
    # With the chain stage gone both replays are the same solve, and the gap is 0.
    assert magnetometer["knee_flexion_rmse_deg"] - auto["knee_flexion_rmse_deg"] >= MIN_KNEE_GAIN_DEG, (
        f"heading = magnetometer: knee flexion {magnetometer['knee_flexion_rmse_deg']}°, auto: "
        f"{auto['knee_flexion_rmse_deg']}°")
