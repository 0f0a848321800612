"""Takes through the Python client (mocapd_client.Takes) against the real mocapd of conftest.py,
fed by the simulated walk: start with the token, stop, list, download raw / BVH / CSV, delete;
and the refusals a client must see as errors (no token, no such take, a take already running)."""

from __future__ import annotations

import tomllib

import pytest

import mocapd_client as mc
from conftest import TOKEN, wait_frames


def http_endpoint(daemon) -> str:
    with open(daemon.dir / "mocapd.toml", "rb") as fh:
        return tomllib.load(fh)["http"]["listen"]


def test_a_take_is_started_stopped_listed_downloaded_and_deleted(walk, tmp_path):
    takes = mc.Takes(http_endpoint(walk.daemon), token=TOKEN)
    name = takes.start(name="py-take", notes="from the python client")
    assert name == "py-take"
    with pytest.raises(mc.TakeError) as running:
        takes.start(name="py-take-2")
    assert running.value.status == 409
    with walk.daemon.client() as c:  # one second of the walk into the take
        c.subscribe(subjects=[1])
        first = wait_frames(c, lambda f: True, 10)
        wait_frames(c, lambda f: f.sync >= first.sync + 100, 10)
    assert takes.stop() == "py-take"

    listed = {t["name"]: t for t in takes.list()}
    assert "py-take" in listed, listed
    take = listed["py-take"]
    assert take["recording"] is False and take["notes"] == "from the python client"
    assert take["raw_bytes"] > 0 and take["samples"] > 0 and take["subjects"] == [1], take
    assert takes.get("py-take")["name"] == "py-take"

    raw = takes.download("py-take", tmp_path / "take.mocapraw")
    assert raw.stat().st_size == take["raw_bytes"]
    bvh = takes.download("py-take", tmp_path / "take.bvh", format="bvh", subject=1).read_text()
    assert bvh.startswith("HIERARCHY") and "MOTION" in bvh
    frames = int(bvh.split("Frames:")[1].split()[0])
    assert frames >= 90, frames  # one second at 100 Hz, give or take the edges
    csv = takes.download("py-take", tmp_path / "take.csv", format="csv").read_text().splitlines()
    assert len(csv) > frames and "left_knee.flexion" in csv[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take.bvh", "take.csv", "take.mocapraw"], \
        "a download leaves its file and nothing else"

    takes.delete("py-take")
    assert "py-take" not in {t["name"] for t in takes.list()}
    with pytest.raises(mc.TakeError) as gone:
        takes.get("py-take")
    assert gone.value.status == 404


def test_refusals_are_errors_with_the_daemons_reason(walk, tmp_path):
    endpoint = http_endpoint(walk.daemon)
    with pytest.raises(mc.TakeError) as no_token:
        mc.Takes(endpoint).start()
    assert no_token.value.status == 401
    with pytest.raises(mc.TakeError) as missing:
        mc.Takes(endpoint).download("no-such-take", tmp_path / "x.bvh", format="bvh")
    assert missing.value.status == 404
    assert list(tmp_path.iterdir()) == [], "a refused download leaves no file"
    with pytest.raises(ValueError):
        mc.Takes(endpoint).download("x", tmp_path / "x", format="fbx")
