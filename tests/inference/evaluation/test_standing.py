"""A walk that ends in a stand: once every measured segment is still, the unmeasured thighs
settle on the stand (inference/evaluation/standing.py). The goal is 5 deg; with the stand
prior (inference/poser/stand_prior.py) the thighs end 0.2-0.3 deg off on these walks, 5.3-5.7
without it (the model's own estimate of a stand, docs/real_signals.md, "A standing body")."""

from __future__ import annotations

import pytest

from inference.evaluation.runner import synthetic_motion
from inference.evaluation.standing import stand_errors, summary
from inference.poser.models import DEFAULT_WEIGHTS, resolve_model


@pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")
def test_thighs_settle_on_a_stand_after_a_walk():
    walks = [synthetic_motion(seconds=4.0, seed=k, speed=1.0 + 0.2 * k) for k in range(2)]
    res = stand_errors(resolve_model("diffusion"), walks, ("pelvis", "l_shank", "r_shank"), stand_s=3.0)
    mean = summary(res)
    for r in res:
        # settling through the stand: its end nearer than its mean from 1 s on, both sides
        assert r.at_end["l_thigh"] < 2.0 and r.at_end["r_thigh"] < 2.0, r
        assert r.deg["l_thigh"] < 3.0 and r.deg["r_thigh"] < 3.0, r
    # the measured segments are what the sensors say
    assert mean["pelvis"] < 2.0 and mean["l_shank"] < 2.0 and mean["r_shank"] < 2.0
