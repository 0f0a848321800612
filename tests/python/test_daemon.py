"""mocapd_client against the real mocapd fed by mocap-sim stream (fixtures in conftest)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import mocapd_client as mc
from conftest import RATE_HZ, TOKEN

SEGMENTS = 15


def test_hello_describes_the_skeleton(walk):
    with walk.daemon.client() as c:
        info = c.info
    assert info.protocol_version == 1
    assert info.world_frame in ("ENU", "NED")
    sk = info.skeleton
    assert len(sk.segment_names) == SEGMENTS
    assert sk.parents[0] == -1 and all(0 <= p < i for i, p in enumerate(sk.parents) if i)
    assert sk.offsets_m.shape == (SEGMENTS, 3)
    for joint in ("left_knee", "right_knee", "left_elbow", "right_elbow"):
        assert f"{joint}.flexion" in sk.joint_angle_names


def test_frames_carry_numpy_poses_of_the_subscribed_fields(walk):
    with walk.daemon.client() as c:
        sub = c.subscribe(subjects=[1], fields=mc.Fields.ALL)
        assert sub.fields == mc.Fields.ALL and sub.subject_ids == [1] and sub.queue_frames > 0
        frames = list(c.frames(count=RATE_HZ))
        names = c.info.skeleton.joint_angle_names
        drops = c.drops_announced
    assert len(frames) == RATE_HZ
    syncs = [f.sync for f in frames]
    assert all(b > a for a, b in zip(syncs, syncs[1:])), "sync only grows"
    if drops == 0:
        assert syncs[-1] - syncs[0] == RATE_HZ - 1, "no frame lost unless announced"
    # One SYNC step is one sample period on the sink's clock. The simulated sink stamps its
    # batches when it actually sends them, so on a loaded machine a second of SYNCs spans up
    # to a few tenths more (seen: 1.047 s for 99 steps at load 8); a wrong unit or rate would
    # be off by a factor.
    span_us = frames[-1].sample_us - frames[0].sample_us
    assert span_us == pytest.approx((syncs[-1] - syncs[0]) * 1e6 / RATE_HZ, rel=0.3)
    for f in frames:
        assert f.subject_id == 1
        assert f.q.shape == (SEGMENTS, 4) and f.p.shape == (SEGMENTS, 3) and f.q_raw.shape == (SEGMENTS, 4)
        assert np.allclose(np.linalg.norm(f.q, axis=1), 1.0, atol=1e-4)
        assert f.all_flagged(mc.SegmentFlags.CALIBRATED)
        assert len(f.joint_angles_rad) == len(names)
        assert f.latency_us is not None and 0 <= f.latency_us < 2_000_000
    # The walk moves: knees bend and the pelvis travels.
    knee = np.array([f.joint_angles["left_knee.flexion"] for f in frames])
    assert np.ptp(np.degrees(knee)) > 10
    assert np.linalg.norm(frames[-1].p[0] - frames[0].p[0]) > 0.3
    d = json.loads(json.dumps(frames[0].to_dict()))
    assert d["subject"] == 1 and len(d["segments"]) == SEGMENTS and d["segments"][0]["name"] == "pelvis"
    assert set(d["joint_angles_rad"]) == set(names)


def test_default_fields_and_decimation(walk):
    with walk.daemon.client() as c:
        sub = c.subscribe(decimation=5)
        assert sub.fields == mc.Fields.ORIENTATIONS | mc.Fields.POSITIONS and sub.decimation == 5
        frames = list(c.frames(count=10))
    assert all(f.joint_angles_rad.size == 0 and f.q_raw.size == 0 and f.q.shape == (SEGMENTS, 4) for f in frames)
    steps = {b.sync - a.sync for a, b in zip(frames, frames[1:])}
    assert steps == {5}


def test_subject_that_does_not_exist_gets_no_frames(walk):
    with walk.daemon.client() as c:
        c.subscribe(subjects=[3])
        assert list(c.frames(duration=0.5)) == []
        assert c.ping() < 1.0  # the connection is alive and answers


def test_stats_counters_move(walk):
    with walk.daemon.client() as c:
        c.subscribe(subjects=[1])
        before = c.stats()
        list(c.frames(count=50))
        after = c.stats()
    assert after.server_time_us > before.server_time_us
    moved = [k for k, v in after.counters.items() if v > before.counters.get(k, 0)]
    assert moved, "some counter moves while frames flow"
    assert all(after.counters[k] >= v for k, v in before.counters.items()), "counters only go up"
    assert after.latencies and all(s.count >= 0 and s.max_us >= s.p50_us for s in after.latencies.values())


@pytest.mark.parametrize("token, reason", [("", "token required"), ("wrong", "bad token")])
def test_control_is_refused_without_the_right_token(walk, token, reason):
    with walk.daemon.client() as c:
        refused_before = {k: v for k, v in c.stats().counters.items() if k.startswith("serve.control_refused")}
        reply = c.control(token, start_recording="")
        assert not reply.ok and reason in reply.error
        assert c.control(token, reload=True).ok is False
        after = c.stats().counters
        assert c.ping() < 1.0, "a refusal does not close the connection"
    grown = {k for k, v in after.items() if k.startswith("serve.control_refused") and v > refused_before.get(k, 0)}
    assert grown, "refusals are counted"
    assert not list(walk.daemon.dir.glob("*.bvh")), "a refused start_recording records nothing"


def test_control_with_the_token_is_accepted(walk):
    with walk.daemon.client() as c:
        assert c.control(TOKEN, reload=True).ok


def test_control_needs_exactly_one_action(walk):
    with walk.daemon.client() as c:
        with pytest.raises(ValueError):
            c.control(TOKEN)
        with pytest.raises(ValueError):
            c.control(TOKEN, reload=True, stop_recording=True)
