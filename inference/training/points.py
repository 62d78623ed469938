"""Tracked VR points for a training window: what a headset, two controllers and a waist
tracker would have reported of the window's clean motion.

Why from the window and not from the dataset: the points are a fixed function of the
segment orientations, the root height and the body (``inference.body.tracked``), all of
which every batch already carries after its augmentations (scale, yaw, mirror), so
computing them here keeps them consistent with whatever the window became, needs no
dataset cache of its own, and serves any dataset.

Per window: tracked or not (``points_share``), the waist tracker or not
(``points_pelvis``); the tracking error of a consumer headset (``sim_devices/devices/
vr_rig.py`` for the sources): a wander of 2 mm per axis held over the window and a jitter of
1 mm per axis and frame. A tracked point's orientation is known to the model as its
segment's orientation (the head, the hands, the pelvis): those entries join the window's
known entries, as an IMU's orientation does for its segment.
"""

from __future__ import annotations

import torch
from torch import Tensor

from inference.body.body import forward_kinematics
from inference.body.rotations import rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS
from inference.body.tracked import POINT_SEGMENTS, point_features, point_locals, point_positions
from inference.features.layout import N_FEATURES, SL_PZ, SL_ROT

JITTER_M = 0.001
WANDER_M = 0.002


def window_points(x: Tensor, offsets: Tensor, height: Tensor, present: Tensor,
                  gen: torch.Generator | None = None, noise: bool = True) -> Tensor:
    """(B, N, 16) position input of windows ``x`` (B, N, F) in physical units, bodies
    ``offsets`` (B, 24, 3) and ``height`` (B,), points ``present`` (B, 4) bool."""
    B, N = x.shape[:2]
    R = rot6d_to_matrix(x[..., SL_ROT].reshape(B, N, N_SEGMENTS, 6))
    root = torch.zeros(B, N, 3, dtype=x.dtype)
    root[..., 2] = x[..., SL_PZ.start]
    joints = forward_kinematics(R, root, offsets[:, None])
    pos = point_positions(R, joints, point_locals(offsets, height)[:, None])
    if noise:
        pos = (pos + WANDER_M * torch.randn(B, 1, pos.shape[2], 3, generator=gen, dtype=pos.dtype)
               + JITTER_M * torch.randn(pos.shape, generator=gen, dtype=pos.dtype))
    return point_features(pos, present[:, None, :])


def draw_presence(B: int, share: float, pelvis: float, gen: torch.Generator | None = None) -> Tensor:
    """(B, 4) which points each window has: none, or head + hands (+ waist tracker)."""
    tracked = torch.rand(B, generator=gen) < share
    waist = tracked & (torch.rand(B, generator=gen) < pelvis)
    return torch.stack([tracked, tracked, tracked, waist], dim=1)


def known_orientations(present: Tensor, window: int) -> Tensor:
    """(B, N, F) bool: the orientation entries of the tracked points' segments."""
    B = present.shape[0]
    m = torch.zeros(B, window, N_FEATURES, dtype=torch.bool)
    for k, seg in enumerate(POINT_SEGMENTS):
        cols = slice(SL_ROT.start + 6 * seg, SL_ROT.start + 6 * seg + 6)
        m[:, :, cols] = present[:, k, None, None]
    return m


__all__ = ["window_points", "draw_presence", "known_orientations", "JITTER_M", "WANDER_M"]
