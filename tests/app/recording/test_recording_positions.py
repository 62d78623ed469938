"""A VR rig's positions in the recording: written beside the rig's sites' other channels,
read back into the frames a replay pushes, so a replay with no options gives back the
live poses whose arms reached the controllers; recordings without positions (IMU
sessions, recordings from before positions were kept) read and replay as before; a
damaged position chunk costs its own frames of that site, as any channel's."""

from __future__ import annotations

import itertools
import shutil

import h5py
import numpy as np
import pytest

from app.live import Pipeline
from app.recording import Recorder, read_recording
from app.replay import replay_recording
from inference.poser.poser import make_poser
from tests.app.rig_frames import RIG_SITES, SITES, Rig, rig_walk

CHUNK = 64


@pytest.fixture(scope="module")
def rig() -> Rig:
    return rig_walk(seconds=3.0)


def record(path, rig: Rig, position_sites=RIG_SITES, reach: bool = True):
    ticks = itertools.count(0.0, 0.01)  # a stepping clock: flushes do not depend on machine speed
    rec = Recorder(path, SITES, metadata={"model": "floor", "steps": 0, "reach": reach}, flush_interval=0.2,
                   chunk=CHUNK, clock=lambda: next(ticks), position_sites=position_sites)
    pipe = Pipeline(make_poser("floor", body=rig.motion.body), SITES, sinks=[rec], reach=reach)
    # before the first frame (a replay takes the frame at a calibration's time for its last
    # calibrating one, as live); at time 0 a calibration would read as zeroed
    pipe.set_calibration(rig.calibration, rig.frames[0].t - 0.01)
    live = []
    for f in rig.frames:
        live += pipe.push(f)
    pipe.close()
    assert rec.closed and len(live) > 40
    return live


def _stack(poses, what: str) -> np.ndarray:
    return np.stack([getattr(lp.pose, what) for lp in poses])


def test_positions_round_trip_and_replay_gives_back_the_reached_poses(tmp_path, rig):
    path = tmp_path / "rig.h5"
    live = record(path, rig)
    assert all(lp.points is not None for lp in live)
    r = read_recording(path)
    assert r.position_sites == RIG_SITES and "position" not in r.raw["pelvis"]
    sent = np.stack([f.position for f in rig.frames])
    np.testing.assert_allclose(r.positions(), sent, atol=1e-5, equal_nan=True)  # float32 on disk
    frames = r.hub_frames()
    assert np.isnan(frames[0].position[0]).all() and np.isfinite(frames[0].position[1:]).all()
    # the recon holds the reached arms, and a replay with no options gives them back
    np.testing.assert_allclose(r.recon["joints"], _stack(live, "joints"), atol=1e-5)
    again = replay_recording(r, make_poser("floor", body=rig.motion.body)).poses
    assert len(again) == len(live) and all(lp.points is not None for lp in again)
    np.testing.assert_allclose(_stack(again, "rot"), _stack(live, "rot"), atol=1e-4)
    np.testing.assert_allclose(_stack(again, "joints"), _stack(live, "joints"), atol=1e-4)
    # asked not to reach, the arms are the model's
    plain = replay_recording(r, make_poser("floor", body=rig.motion.body), reach=False).poses
    assert all(lp.points is None for lp in plain)
    assert np.abs(_stack(plain, "joints") - _stack(live, "joints")).max() > 0.02


def test_a_session_that_did_not_reach_replays_without_reaching(tmp_path, rig):
    path = tmp_path / "no-reach.h5"
    live = record(path, rig, reach=False)
    r = read_recording(path)
    assert r.metadata["reach"] is False and r.position_sites == RIG_SITES
    again = replay_recording(r, make_poser("floor", body=rig.motion.body)).poses
    assert all(lp.points is None for lp in again)
    np.testing.assert_allclose(_stack(again, "joints"), _stack(live, "joints"), atol=1e-4)


def test_a_recording_without_positions_reads_and_replays_as_before(tmp_path, rig):
    """As an IMU session's or one from before positions were kept: no position dataset."""
    path = tmp_path / "old.h5"
    record(path, rig, position_sites=(), reach=False)
    with h5py.File(path, "r") as f:
        assert not any("position" in f[f"raw/{s}"] for s in SITES)
    r = read_recording(path)
    assert r.position_sites == () and r.positions() is None and r.damage == []
    assert all(f.position is None for f in r.hub_frames()[:5])
    poses = replay_recording(r, make_poser("floor", body=rig.motion.body)).poses
    assert poses and all(lp.points is None for lp in poses)
    np.testing.assert_allclose(_stack(poses, "joints"), r.recon["joints"], atol=1e-4)


def test_a_damaged_position_chunk_costs_that_sites_frames(tmp_path, rig):
    good = tmp_path / "good.h5"
    record(good, rig)
    orig = read_recording(good)
    bad = tmp_path / "bad.h5"
    shutil.copy(good, bad)
    row = CHUNK + 5
    with h5py.File(good, "r") as f:
        info = f["raw/r_wrist/position"].id.get_chunk_info_by_coord((row, 0))
    with open(bad, "r+b") as fh:
        fh.seek(info.byte_offset + info.size // 2)
        fh.write(b"\x13\x37\xde\xad\xbe\xef\x00\x01")
    r = read_recording(bad)
    a, b = CHUNK, 2 * CHUNK
    assert len(r.damage) == 1 and r.damage[0].startswith(f"raw/r_wrist/position frames {a}-{b - 1} ")
    w = r.raw["r_wrist"]
    assert not w["present"][a:b].any() and np.isnan(w["position"][a:b]).all()
    keep = np.r_[0:a, b:r.n_frames]
    assert np.array_equal(w["position"][keep], orig.raw["r_wrist"]["position"][keep], equal_nan=True)
    assert np.array_equal(r.raw["head"]["position"], orig.raw["head"]["position"], equal_nan=True)


def test_positions_are_only_for_the_recordings_sites(tmp_path):
    with pytest.raises(ValueError, match="position site"):
        Recorder(tmp_path / "x.h5", SITES, position_sites=("l_hand",))
