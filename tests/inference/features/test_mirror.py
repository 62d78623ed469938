"""Mirror images of feature windows and the mirror-averaged denoiser (inference/features/mirror.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.features.layout import N_FEATURES, SL_CONTACT, SL_DP, WINDOW, observation_mask
from inference.features.mirror import MirrorAveraged, mirror_features, mirror_points
from inference.model.config import ModelConfig
from inference.model.denoiser import freeze_for_cpu
from inference.model.files import build_model


def test_mirror_features_equal_the_features_of_the_mirrored_motion():
    """Reflect a walk physically (world y -> -y, left <-> right, on the mirrored body) and
    derive its features from scratch: they must equal mirror_features of the original's,
    orientations, accelerations, root motion and contacts alike."""
    from inference.body.body import Body
    from inference.body.motion import Motion
    from inference.body.skeleton import SEGMENTS
    from inference.evaluation.runner import synthetic_motion
    from inference.features.codec import features_from_motion

    m = synthetic_motion(seconds=3.0)
    M = np.diag([1.0, -1.0, 1.0])
    swap = [SEGMENTS.index({"l_": "r_", "r_": "l_"}.get(n[:2], n[:2]) + n[2:]) for n in SEGMENTS]
    off = mirror_points(torch.as_tensor(m.body.offsets), SEGMENTS).numpy()
    mm = Motion(rot=M @ m.rot[:, swap] @ M, root=m.root @ M, fps=m.fps,
                body=Body.from_offsets(off, m.body.height), name="mirrored")
    x = features_from_motion(m)
    xm = features_from_motion(mm)
    assert x[:, SL_CONTACT].std() > 0 and np.abs(x[:, SL_DP]).max() > 0  # a real walk, not a still pose
    got = mirror_features(torch.as_tensor(x)).numpy()
    np.testing.assert_allclose(got, xm, atol=1e-4)
    assert not np.allclose(got, x, atol=1e-2)
    np.testing.assert_array_equal(mirror_features(mirror_features(torch.as_tensor(x))).numpy(), x)


def _norm_stats(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(N_FEATURES, generator=g) * 0.3, torch.rand(N_FEATURES, generator=g) + 0.5


def _inputs(batch: int = 2, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    z = torch.randn(batch, WINDOW, N_FEATURES, generator=g)
    mask = torch.as_tensor(np.broadcast_to(observation_mask(["pelvis", "l_wrist", "l_shank"]), z.shape).copy())
    return z, torch.tensor([1000, 400][:batch]), torch.tensor([1.6, 1.8][:batch]), mask


@pytest.mark.parametrize("kind", ["diffusion", "regressor"])
def test_the_averaged_model_answers_a_mirror_image_with_the_mirror_image_of_its_answer(kind):
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    cfg.mask_input = True
    net = build_model(kind, cfg).eval()
    mean, std = _norm_stats()
    sym = MirrorAveraged(net, mean, std)
    z, t, h, mask = _inputs()
    args = (t, h, mask) if kind == "diffusion" else (mask, h)
    margs = (t, h, mask[..., sym.idx]) if kind == "diffusion" else (mask[..., sym.idx], h)
    with torch.no_grad():
        y, ym = sym(z, *args), sym(sym.mirror(z), *margs)
        plain, plain_m = net(z, *args), net(sym.mirror(z), *margs)
    torch.testing.assert_close(ym, sym.mirror(y), atol=1e-5, rtol=1e-5)
    # the model alone has no such symmetry: the test would catch an average that did nothing
    assert (plain_m - sym.mirror(plain)).abs().max() > 1e-2
    # one batched call equals the two calls it stands for
    torch.testing.assert_close(y, 0.5 * (plain + sym.mirror(plain_m)), atol=1e-5, rtol=1e-5)


def test_the_mirror_in_normalised_units_is_the_feature_mirror_and_its_own_inverse():
    mean, std = _norm_stats()
    sym = MirrorAveraged(torch.nn.Identity(), mean, std)
    x = torch.randn(3, WINDOW, N_FEATURES)
    torch.testing.assert_close(sym.mirror(x) * std + mean, mirror_features(x * std + mean), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(sym.mirror(sym.mirror(x)), x, atol=1e-5, rtol=1e-5)
    phys, phys_m = x * std + mean, sym.mirror(x) * std + mean
    torch.testing.assert_close(phys_m[..., SL_CONTACT.start], phys[..., SL_CONTACT.start + 2])  # l_heel <- r_heel
    torch.testing.assert_close(phys_m[..., SL_DP.start], phys[..., SL_DP.start])  # forward stays forward
    torch.testing.assert_close(phys_m[..., SL_DP.start + 1], -phys[..., SL_DP.start + 1])  # left turns right


def test_the_live_loops_frozen_trace_of_two_windows_serves_the_average():
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    cfg.mask_input = True
    net = build_model("diffusion", cfg).eval()
    mean, std = _norm_stats()
    z, t, h, mask = _inputs(batch=1)
    with torch.no_grad():
        eager = MirrorAveraged(net, mean, std)(z, t, h, mask)
        traced = MirrorAveraged(freeze_for_cpu(net, batch=2), mean, std)(z, t, h, mask)
    torch.testing.assert_close(traced, eager, atol=1e-5, rtol=1e-5)
