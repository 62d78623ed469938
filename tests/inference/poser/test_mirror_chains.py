"""Mirror averaging of whole inpainting chains (``Poser(mirror_chains=True)``): equivariant
exactly, so a body measured symmetric gets symmetric legs, and batched as frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.rotations import matrix_to_rot6d
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX, SITE_SEGMENT_INDEX
from inference.features.layout import N_FEATURES, SL_ROT, observation_mask
from inference.poser.batched import reconstruct_many
from inference.poser.models import DEFAULT_WEIGHTS, resolve_model
from inference.poser.poser import Poser, reconstruct_offline

from .test_batched import SHIPPED, _close
from .tiny import tiny_diffusion

pytestmark = pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")


def _standing(T: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis and both shanks upright and still, facing +X: a stand that is its own mirror image."""
    sites = ("pelvis", "l_shank", "r_shank")
    F = np.zeros((T, N_FEATURES))
    for s in sites:
        seg = SITE_SEGMENT_INDEX[SITE_INDEX[s]]
        F[:, SL_ROT.start + 6 * seg: SL_ROT.start + 6 * seg + 6] = matrix_to_rot6d(np.eye(3))
    return F, np.broadcast_to(observation_mask(sites), (T, N_FEATURES)).copy()


def _thighs(rec) -> tuple[float, float]:
    out = []
    for seg in ("l_thigh", "r_thigh"):
        d = rec.rot[-20:, SEGMENT_INDEX[seg]][:, :, 2]  # each frame's third column: the segment's Z in the world
        out.append(float(np.degrees(np.arccos(np.clip(d[:, 2], -1, 1))).mean()))
    return out[0], out[1]


def test_a_symmetric_stand_gets_symmetric_thighs():
    model = resolve_model("diffusion")
    F, M = _standing()
    # the model's own stand: the stand prior would straighten both knees whatever answered
    chains = reconstruct_offline(Poser(model, body=1.75, mirror_chains=True, stand_prior=False), F, M)
    left, right = _thighs(chains)
    assert left > 1.0 and abs(left - right) < 0.05
    # mirror averaging of each call leaves the data mean's handedness in the answer
    calls = reconstruct_offline(Poser(model, body=1.75, mirror_chains=False, stand_prior=False), F, M)
    left_c, right_c = _thighs(calls)
    assert abs(left_c - right_c) > 10 * abs(left - right)


def test_chains_in_lock_step_are_each_their_frame_by_frame_reconstruction():
    from inference.evaluation.runner import clip_input, synthetic_motion

    model = tiny_diffusion()
    clips = [clip_input(synthetic_motion(seconds=1.5, seed=k), ("pelvis", "l_shank", "r_shank")) for k in range(2)]

    def posers():
        return [Poser(model, body=1.75, steps=3, mirror=True, mirror_chains=True, **SHIPPED) for _ in clips]

    assert all(p.chain_mirror for p in posers())
    seq = [reconstruct_offline(p, c.features, c.mask) for p, c in zip(posers(), clips)]
    many = reconstruct_many(posers(), [(c.features, c.mask) for c in clips], lanes=2)
    for a, b in zip(seq, many):
        _close(a, b)
