"""Augmentations that keep a window physically consistent: a turn about the vertical and
a change of body scale, applied to features in place of re-synthesising the motion."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from inference.body.rotations import matrix_about_axis
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
    Rz = matrix_about_axis(torch.tensor([0.0, 0.0, 1.0], dtype=x.dtype), angle.to(x.dtype))[:, None, None, :2, :2]
    idx = torch.tensor(horizontal_pairs())
    out = x.clone()
    out[..., idx] = (Rz @ x[..., idx][..., None])[..., 0]  # each (x, y) pair of a window, (B, N, P, 2)
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


def _shift(v: Tensor, lag: Tensor) -> Tensor:
    """Signals (B, N, S, C) read ``lag`` (B, S) frames later (linear interpolation, the
    window's ends held)."""
    B, N = v.shape[:2]
    t = torch.arange(N, dtype=v.dtype)[None, :, None] + lag[:, None, :]  # (B, N, S)
    t = t.clamp(0, N - 1)
    i0 = t.floor().long().clamp(max=N - 2)
    w = (t - i0.to(v.dtype))[..., None]
    g0 = torch.gather(v, 1, i0[..., None].expand(*i0.shape, v.shape[-1]))
    g1 = torch.gather(v, 1, (i0 + 1)[..., None].expand(*i0.shape, v.shape[-1]))
    return g0 * (1 - w) + g1 * w


def sensor_effects(x: Tensor, fx, gen: torch.Generator) -> Tensor:
    """Windows (B, N, F) of unnormalised features as real, calibrated sensors would report
    the 13 sites' orientations and accelerations (``config.SensorEffects`` ``fx``): a
    residual mounting rotation in the bone frame, a heading error of the sensor's world
    frame (orientation and acceleration), an acceleration gain, white noise and a time
    lag, each drawn per window and site; a share 1 - ``fx.p`` of the windows is left
    clean. Only the sites' entries change, so the unmeasured segments the model infers
    keep their true values as targets."""
    from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix
    from inference.body.skeleton import N_SITES, SITE_SEGMENT_INDEX

    B, N, _ = x.shape
    S = N_SITES
    dt = x.dtype
    seg = torch.tensor(SITE_SEGMENT_INDEX)
    rot_idx = (SL_ROT.start + 6 * seg[:, None] + torch.arange(6)[None]).reshape(-1)  # (S*6,)
    acc_idx = torch.arange(SL_ACC.start, SL_ACC.stop)
    R = rot6d_to_matrix(x[..., rot_idx].reshape(B, N, S, 6))  # (B, N, S, 3, 3)
    a = x[..., acc_idx].reshape(B, N, S, 3)
    on = (torch.rand(B, generator=gen) < fx.p).to(dt)[:, None]  # (B, 1)
    if fx.lag_frames > 0:
        lag = (2 * torch.rand(B, S, generator=gen) - 1) * fx.lag_frames * on
        R = _shift(R.reshape(B, N, S, 9), lag).reshape(B, N, S, 3, 3)
        R = rot6d_to_matrix(matrix_to_rot6d(R))  # the blend of two rotations back onto SO(3)
        a = _shift(a, lag)
    if fx.mount_deg > 0:
        axis = torch.randn(B, S, 3, generator=gen)
        axis = axis / axis.norm(dim=-1, keepdim=True)
        ang = torch.rand(B, S, generator=gen) * math.radians(fx.mount_deg) * on
        R = R @ matrix_about_axis(axis, ang)[:, None]
    if fx.heading_deg > 0:
        ang = (2 * torch.rand(B, S, generator=gen) - 1) * math.radians(fx.heading_deg) * on
        Rz = matrix_about_axis(torch.tensor([0.0, 0.0, 1.0]).expand(B, S, 3), ang)[:, None]  # (B, 1, S, 3, 3)
        R = Rz @ R
        a = (Rz @ a[..., None])[..., 0]
    if fx.acc_gain > 0 or fx.acc_scale != 1.0:
        gain = 1 + (2 * torch.rand(B, 1, S, 1, generator=gen) - 1) * fx.acc_gain if fx.acc_gain > 0 else 1.0
        a = a * (1 + (fx.acc_scale * gain - 1) * on[:, :, None, None])
    if fx.acc_noise > 0:
        a = a + torch.randn(a.shape, generator=gen) * fx.acc_noise * on[:, :, None, None]
    out = x.clone()
    out[..., rot_idx] = matrix_to_rot6d(R).reshape(B, N, S * 6).to(dt)
    out[..., acc_idx] = a.reshape(B, N, S * 3).to(dt)
    return torch.where(on[:, :, None] > 0, out, x)
