"""A recording written before the live frame became typed replays to the same poses (1e-6 then;
5e-5 since the step around the model call runs on numpy, whose float32 rounding moves this tiny
model's orientations by up to 1.7e-5, where a field read from the wrong place moves them by
orders of magnitude more):
orientations, accelerations, which sites are observed, the insoles' contacts and a VR rig's
tracked points all reach the answer of the guard's model, so a field read from the wrong
place changes them (the fixture and how it was made: ``frame_fixture.py``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.recording import read_recording
from app.replay import replay_recording
from inference.poser.poser import make_poser
from tests.app.live.frame_fixture import poses_arrays

DATA = Path(__file__).parent / "data"


def test_a_recording_from_before_the_typed_frame_replays_to_the_same_poses():
    want = np.load(DATA / "frame_guard.npz")
    rec = read_recording(DATA / "frame_guard.h5")
    poser = make_poser(DATA / "frame_guard.pt", body=float(rec.metadata["body_height_m"]), steps=2, seed=0)
    got = poses_arrays(replay_recording(rec, poser).poses)
    # every channel is in play: insoles, a dropped site, tracked hands the arms reached for
    assert want["insoles"].sum() > 50 and want["reached"].sum() > 50
    assert (~want["observed"][:, 3]).any() or (~want["observed"]).any()
    for k in ("t", "observed", "insoles", "reached"):
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    for k in ("rot", "root", "joints"):
        np.testing.assert_allclose(got[k], want[k], rtol=0, atol=5e-5, err_msg=k)
