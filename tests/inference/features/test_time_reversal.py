"""Features played backwards are those of the motion played backwards; which clips count as
forward walks; and that forward walks played backwards teach the pelvis odometry a real
backward walk."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.motion import Motion
from inference.evaluation.runner import synthetic_motion
from inference.features.codec import features_from_motion
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT
from inference.features.time_reversal import is_forward_walk, reverse_features


def test_reversed_features_are_those_of_the_motion_played_backwards():
    """Orientations, accelerations (second difference, centred moving average), height and
    the root steps of the motion reversed at 60 Hz match the reversed 20 Hz features."""
    m = synthetic_motion(seconds=4.0, speed=1.3, turn_deg_per_s=25.0, seed=3)
    assert (m.n_frames - 1) % 3 == 0  # both ends fall on the 20 Hz grid
    back = Motion(m.rot[::-1], m.root[::-1], m.fps, m.body, name="backwards")
    want = features_from_motion(back)
    got = reverse_features(features_from_motion(m))
    assert got.shape == want.shape == (len(want), N_FEATURES)
    inner = slice(4, -4)  # the moving average's edges repeat a neighbour
    for sl, tol in ((SL_ROT, 1e-6), (SL_ACC, 1e-3), (SL_DP, 1e-6), (SL_PZ, 1e-6)):
        assert np.abs(got[inner, sl] - want[inner, sl]).max() < tol, sl
    assert np.abs(got[:, SL_DP]).sum() > 1.0  # the clip walks
    # contacts come from foot speeds, the same either way round
    assert (got[inner, SL_CONTACT] == want[inner, SL_CONTACT]).mean() > 0.95


def test_played_back_twice_is_the_clip_and_traces_the_path_backwards():
    x = features_from_motion(synthetic_motion(seconds=3.0, seed=1))
    r = reverse_features(x)
    path, back = np.cumsum(x[:, SL_DP], axis=0), np.cumsum(r[:, SL_DP], axis=0)
    assert np.allclose(back, path[::-1] - path[-1], atol=1e-5)
    twice = reverse_features(r)
    assert np.array_equal(twice[1:], x[1:]) and np.allclose(twice[0, SL_DP], 0)


def _clip(step_forward: float, step_left: float = 0.0, flight_share: float = 0.0, frames: int = 200):
    """Features with only the contacts set, and the root steps in the heading frame."""
    x = np.zeros((frames, N_FEATURES), np.float32)
    x[:, SL_CONTACT] = 1.0
    x[: int(flight_share * frames), SL_CONTACT] = 0.0
    steps = np.tile(np.float32([step_forward, step_left]), (frames, 1))
    return x, steps


@pytest.mark.parametrize("clip, forward_walk", [
    (_clip(1.2 / 20), True),  # a walk
    (_clip(1.2 / 20, 0.2 / 20), True),  # drifting a little to the side
    (_clip(-1.2 / 20), False),  # a backward walk already
    (_clip(0.3 / 20, 1.0 / 20), False),  # side steps
    (_clip(3.0 / 20), False),  # a run's pace
    (_clip(1.2 / 20, flight_share=0.3), False),  # hops, or a jog: off the ground a third of the time
    (_clip(0.0), False),  # standing
])
def test_forward_walks_are_picked(clip, forward_walk):
    assert is_forward_walk(*clip) is forward_walk


@pytest.mark.data
def test_forward_walks_played_backwards_teach_a_real_backward_walk(shared_data):
    """Trained on the other styles' forward walks only, the odometry sends the held-out sad
    backward walk *forward* (7.1 of 5.6 m the wrong way when written); with those walks
    also played backwards it goes backward, and the forward walk still goes forward."""
    from inference.loaders import load_motion
    from inference.poser.pelvis_odometry import OdometryTraining, clip_displacements, train_odometry

    d1 = shared_data / "bandai" / "d1"
    files = sorted(f for f in d1.glob("dataset-1_walk_*_00[12].bvh.gz") if "_sad_" not in f.name)
    train = [features_from_motion(load_motion(f)) for f in files]
    back = features_from_motion(load_motion(d1 / "dataset-1_walk-back_sad_001.bvh.gz"))
    forward = features_from_motion(load_motion(d1 / "dataset-1_walk_sad_001.bvh.gz"))

    def direction(odo, x):  # cosine between the odometry's net travel and the truth's
        p, t = clip_displacements(odo, x).sum(0), x[:, SL_DP].sum(0)
        return float(p @ t / np.linalg.norm(p) / np.linalg.norm(t))

    cfgs = {rev: OdometryTraining(steps=800, batch=256, reverse_walks=rev) for rev in (False, True)}
    odos = {rev: train_odometry(train, None, cfg, progress=None) for rev, cfg in cfgs.items()}
    assert odos[True].meta["reversed_walks"] >= 12 and "reversed_walks" not in odos[False].meta
    assert direction(odos[False], back) < 0  # the data has no backward walk: it goes forward
    assert direction(odos[True], back) > 0.9
    assert direction(odos[True], forward) > 0.9
