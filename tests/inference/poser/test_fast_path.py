"""The live step's numpy path around the model call gives the poses of the torch code it
replaced (reference_poser.py, which composes the library's general torch functions as the
step did): a clip reconstructed frame by frame with the shipped model, at several sensor
sets, with insoles, with the confidence on, and with dropouts, to 1e-5."""

from __future__ import annotations

import numpy as np
import pytest

from inference.evaluation.runner import SIX, clip_input, synthetic_motion
from inference.features.layout import N_FEATURES
from inference.poser.confidence import ConfidenceSettings
from inference.poser.models import DEFAULT_WEIGHTS, resolve_model
from inference.poser.poser import Poser, reconstruct_offline
from tests.inference.poser.reference_poser import ReferencePoser

TOL = 1e-5
CASES = {
    "six": dict(sites=SIX),
    "pelvis_shanks": dict(sites=("pelvis", "l_shank", "r_shank")),
    "shanks": dict(sites=("l_shank", "r_shank")),
    "six_insoles": dict(sites=SIX, insoles=True),
    "six_confidence": dict(sites=SIX, confidence=ConfidenceSettings(draws=2)),
    "pelvis_wrists": dict(sites=("pelvis", "l_wrist", "r_wrist")),  # the pelvis odometry's root
    "pelvis_wrists_dropouts": dict(sites=("pelvis", "l_wrist", "r_wrist"), dropouts=True),  # its windows kept
    "thighs_dropouts": dict(sites=("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank"), dropouts=True),
}


def _clip(spec: dict, seconds: float = 3.5):
    m = synthetic_motion(seconds=seconds, seed=3, height=1.7)
    inp = clip_input(m, spec["sites"], insoles=spec.get("insoles", False))
    feats, mask = inp.features.copy(), inp.mask.copy()
    if spec.get("dropouts"):  # sensors missing for a few frames (NaN where not measured)
        rng = np.random.default_rng(1)
        for t in range(0, len(mask), 17):
            mask[t: t + 3, rng.integers(0, N_FEATURES, 40)] = False
        feats[~mask] = np.nan
    return m, feats, mask


def assert_same_poses(a, b, tol: float = TOL) -> None:
    for name in ("rot", "root", "joints", "contact_prob"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=tol, err_msg=name)
    np.testing.assert_array_equal(a.contacts, b.contacts)
    # physical units (accelerations up to ~20 m/s^2): float32's rounding is relative
    np.testing.assert_allclose(a.features, b.features, rtol=tol, atol=tol, err_msg="features")
    np.testing.assert_allclose(a.root_spread_m, b.root_spread_m, rtol=0, atol=tol)
    # an angle between float32 rotations in degrees (arccos near 1): tests/inference/poser/test_batched.py
    np.testing.assert_allclose(a.spread_deg, b.spread_deg, rtol=0, atol=1e-3)


@pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")
@pytest.mark.parametrize("case", list(CASES))
def test_shipped_model_poses_as_the_torch_step_did(case):
    spec = CASES[case]
    model = resolve_model("diffusion")
    m, feats, mask = _clip(spec)
    got = [reconstruct_offline(cls(model, body=m.body, confidence=spec.get("confidence")), feats, mask)
           for cls in (Poser, ReferencePoser)]
    assert len(got[0]) > model.config.window + 1  # the double-length history buffer wraps at least once
    assert_same_poses(*got)


@pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")
@pytest.mark.parametrize("kw", [dict(history="reconstructed", noise="fixed"), dict(smoothing=False, knee_hinge=False),
                                dict(stride_scale=False, contact_detector=None, pelvis_odometry=None)])
def test_other_settings_pose_as_the_torch_step_did(kw):
    # the shipped model: a random one's poses are far from human, and a knee bent off its hinge
    # plane makes the hinge angle ill-conditioned (float32 rounding then moves it by ~1e-4)
    model = resolve_model("diffusion")
    m, feats, mask = _clip(CASES["thighs_dropouts"])
    got = [reconstruct_offline(cls(model, body=m.body, **kw), feats, mask) for cls in (Poser, ReferencePoser)]
    assert_same_poses(*got)


def test_floor_baseline_poses_as_the_torch_step_did():
    m, feats, mask = _clip(CASES["six"], seconds=2.0)
    assert_same_poses(*[reconstruct_offline(cls(None, body=m.body), feats, mask) for cls in (Poser, ReferencePoser)])
