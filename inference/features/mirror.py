"""Left-right mirror images of motion features, and a denoiser made mirror-symmetric.

A body reflected in its sagittal plane (world y -> -y, left and right swapped) moves as a
body can, so the training data is doubled that way (``TrainConfig.augment_mirror``). The
same symmetry serves at inference: ``MirrorAveraged`` asks the denoiser about the window
and about its mirror image in one batched call and averages the two answers (the second
mirrored back). A model that learnt a handedness from two right-handed HDM05 actors then
cannot impose it on a person it has not seen: the averaged answer is the same for a
motion and its mirror image (docs/model.md, "Inference: steps, start, noise, mirror, history").
"""

from __future__ import annotations

import functools

import numpy as np
import torch
from torch import Tensor, nn

from inference.body.skeleton import CONTACTS, SEGMENTS, SITES
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_ROT


def swap_sides(names: tuple[str, ...]) -> list[int]:
    """Index of each name's left/right counterpart (itself for midline names)."""
    flip = {"l_": "r_", "r_": "l_"}
    return [names.index(flip[n[:2]] + n[2:]) if n[:2] in flip else i for i, n in enumerate(names)]


@functools.lru_cache(maxsize=1)
def mirror_tables() -> tuple[np.ndarray, np.ndarray]:
    """(source index, sign) per feature such that ``x[..., index] * sign`` is the frame of
    the same motion reflected in the sagittal plane (world y -> -y, M = diag(1, -1, 1)),
    left and right swapped.

    The body's rest pose is the identity for every segment and its offsets are mirror
    images of each other, so the mirrored orientation of a segment is M R M of its
    counterpart: its first 6D column (R e_x) maps to M c0, the second (R e_y) to -M c1.
    Site accelerations map to M a, dp to (x, -y); contacts swap sides.
    """
    idx = np.arange(N_FEATURES)
    sign = np.ones(N_FEATURES, dtype=np.float32)
    seg, site, con = swap_sides(SEGMENTS), swap_sides(SITES), swap_sides(CONTACTS)
    for i, j in enumerate(seg):
        idx[SL_ROT.start + 6 * i: SL_ROT.start + 6 * i + 6] = SL_ROT.start + 6 * j + np.arange(6)
        sign[SL_ROT.start + 6 * i: SL_ROT.start + 6 * i + 6] = (1, -1, 1, -1, 1, -1)
    for i, j in enumerate(site):
        idx[SL_ACC.start + 3 * i: SL_ACC.start + 3 * i + 3] = SL_ACC.start + 3 * j + np.arange(3)
        sign[SL_ACC.start + 3 * i: SL_ACC.start + 3 * i + 3] = (1, -1, 1)
    sign[SL_DP.start + 1] = -1
    for i, j in enumerate(con):
        idx[SL_CONTACT.start + i] = SL_CONTACT.start + j
    return idx, sign


def mirror_features(x: Tensor) -> Tensor:
    """Windows (..., F) of unnormalised features reflected left <-> right (see mirror_tables)."""
    idx, sign = _mirror_tensors()
    return x[..., idx] * sign.to(x.dtype)


@functools.lru_cache(maxsize=1)
def _mirror_tensors() -> tuple[Tensor, Tensor]:
    """mirror_tables as tensors, built once: the augmentation runs on every training step."""
    idx, sign = mirror_tables()
    return torch.as_tensor(idx), torch.as_tensor(sign)


def mirror_points(p: Tensor, names: tuple[str, ...]) -> Tensor:
    """Per-name 3-vectors (..., len(names), 3) in a segment frame (bone offsets, contact
    points) for the mirrored body: sides swapped, y negated."""
    out = p[..., swap_sides(names), :].clone()
    out[..., 1] = -out[..., 1]
    return out


class MirrorAveraged(nn.Module):
    """``f_sym(z) = (f(z) + P f(P z)) / 2`` for a denoiser (or the regressor) ``f`` on *normalised* windows,
    with ``P`` the mirror image (``mirror_features``) expressed in normalised units.

    Called like the wrapped model: the denoiser's ``(z, t, height[, mask])`` or the
    regressor's ``(x, mask, height)``; masks are mirrored too. Both
    halves go through the wrapped model as one batch of 2B windows, which on a CPU costs
    less than two calls. ``P`` is an involution, so it also maps the answer back. The
    average of two 6D rotations is not a rotation; the poser's Gram-Schmidt
    (``rot6d_to_matrix``) makes it one, as it does for every model output."""

    def __init__(self, model: nn.Module, mean: Tensor | np.ndarray, std: Tensor | np.ndarray) -> None:
        super().__init__()
        self.model = model
        self.config = getattr(model, "config", None)
        idx, sign = mirror_tables()
        mean = torch.as_tensor(mean, dtype=torch.float32)
        std = torch.as_tensor(std, dtype=torch.float32)
        sign = torch.as_tensor(sign, dtype=torch.float32)
        self.register_buffer("idx", torch.as_tensor(idx), persistent=False)
        # P_n(x) = ((x * std + mean)[idx] * sign - mean) / std = x[idx] * scale + shift
        self.register_buffer("scale", std[idx] * sign / std, persistent=False)
        self.register_buffer("shift", (mean[idx] * sign - mean) / std, persistent=False)

    def mirror(self, x: Tensor) -> Tensor:
        return x[..., self.idx] * self.scale + self.shift

    def forward(self, x: Tensor, *rest: Tensor, points: Tensor | None = None) -> Tensor:
        """``x`` (B, N, F) normalised window; ``rest`` as the wrapped model takes them:
        per-window tensors (B,) (level, height) are repeated, masks (B, N, F) mirrored;
        ``points`` (B or 1, N, 16): tracked points' input, mirrored (``mirror_point_features``)."""
        b = x.shape[0]
        args = [torch.cat([a, a[..., self.idx]]) if a.dim() == x.dim() else torch.cat([a, a]) for a in rest]
        if points is not None:
            from inference.body.tracked import mirror_point_features

            p = points.expand(b, -1, -1)
            y = self.model(torch.cat([x, self.mirror(x)]), *args, points=torch.cat([p, mirror_point_features(p)]))
            return 0.5 * (y[:b] + self.mirror(y[b:]))
        y = self.model(torch.cat([x, self.mirror(x)]), *args)
        return 0.5 * (y[:b] + self.mirror(y[b:]))


__all__ = ["swap_sides", "mirror_tables", "mirror_features", "mirror_points", "MirrorAveraged"]
