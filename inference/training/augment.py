"""Augmentations that keep a window physically consistent: a turn about the vertical and
a change of body scale, applied to features in place of re-synthesising the motion."""

from __future__ import annotations

import torch
from torch import Tensor

from inference.body.skeleton import N_SEGMENTS
from inference.features.layout import (
    SL_ACC,
    SL_DP,
    SL_PZ,
    SL_ROT,
)


def horizontal_pairs() -> list[tuple[int, int]]:
    """Indices (x, y) of every horizontal vector component pair in the frame layout: the
    two 6D columns of each segment, each site acceleration, and dp."""
    pairs = []
    for start, n in ((SL_ROT.start, 2 * N_SEGMENTS), (SL_ACC.start, (SL_ACC.stop - SL_ACC.start) // 3)):
        pairs += [(start + 3 * k, start + 3 * k + 1) for k in range(n)]
    pairs.append((SL_DP.start, SL_DP.start + 1))
    return pairs


def rotate_yaw(x: Tensor, angle: Tensor) -> Tensor:
    """Rotate windows (B, N, F) of unnormalised features about the world vertical by
    ``angle`` (B,) radians: orientations (both 6D columns), site accelerations and root
    displacement turn together; height and contacts are unchanged.

    Heading is arbitrary in the data (it depends on where each capture faced), so the
    model should not learn it; this also multiplies the effective data.
    """
    c = torch.cos(angle).to(x.dtype)[:, None, None]
    s = torch.sin(angle).to(x.dtype)[:, None, None]
    idx = torch.tensor(horizontal_pairs())
    xi, yi = idx[:, 0], idx[:, 1]
    out = x.clone()
    vx, vy = x[..., xi], x[..., yi]
    out[..., xi] = c * vx - s * vy
    out[..., yi] = s * vx + c * vy
    return out


def scale_features(x: Tensor, scale: Tensor) -> Tensor:
    """Windows (B, N, F) of unnormalised features of the same motion on a body ``scale``
    (B,) times as large (``Motion.scaled``): site accelerations (gravity-free), root
    displacement and root height scale, orientations do not. Contact labels are kept: a
    planted foot of a larger body is still planted, though its 0.3 m/s label threshold
    would move a few borderline frames."""
    out = x.clone()
    s = scale.to(x.dtype)[:, None, None]
    for sl in (SL_ACC, SL_DP, SL_PZ):
        out[..., sl] = x[..., sl] * s
    return out
