"""``sensor_effects``: real sensors' errors on the measured features of a training window,
and nothing else."""

from __future__ import annotations

import math

import numpy as np
import torch

from inference.body.rotations import matrix_angle_between, rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS, SITE_SEGMENT_INDEX
from inference.features.layout import SL_ACC, SL_ROT
from inference.training.augment import sensor_effects
from inference.training.config import SensorEffects, TrainConfig
from inference.training.data import synthetic_dataset


def _windows(seed: int = 0) -> torch.Tensor:
    ds = synthetic_dataset(clips=4, frames=61, seed=seed)
    return torch.as_tensor(np.stack(ds.clips), dtype=torch.float32)


def _rot(x: torch.Tensor) -> np.ndarray:
    return rot6d_to_matrix(x[..., SL_ROT].reshape(*x.shape[:2], N_SEGMENTS, 6).double()).numpy()


def test_off_and_p_zero_leave_windows_untouched():
    x = _windows()
    g = torch.Generator().manual_seed(0)
    assert torch.equal(sensor_effects(x, SensorEffects(p=0.0, mount_deg=10.0), g), x)
    assert not SensorEffects(p=1.0).active and SensorEffects(p=0.5, acc_noise=0.1).active


def test_mounting_and_heading_stay_within_their_bounds_on_the_sites_only():
    x = _windows()
    g = torch.Generator().manual_seed(1)
    y = sensor_effects(x, SensorEffects(p=1.0, mount_deg=8.0, heading_deg=5.0), g)
    ang = np.degrees(matrix_angle_between(_rot(y), _rot(x)))  # (B, N, 24)
    sites = sorted(set(SITE_SEGMENT_INDEX))
    others = [k for k in range(N_SEGMENTS) if k not in sites]
    assert ang[..., others].max() < 1e-3  # what the model infers keeps its truth
    assert ang[..., sites].max() < 8.0 + 5.0 + 0.1 and ang[..., sites].mean() > 1.0
    # a heading error turns the acceleration with the orientation: its norm is kept
    na, nb = (np.linalg.norm(v[..., SL_ACC].reshape(4, 61, -1, 3).numpy(), axis=-1) for v in (x, y))
    assert np.allclose(na, nb, atol=1e-4)


def test_gain_noise_and_lag_change_the_accelerations_as_drawn():
    x = _windows(2)
    g = torch.Generator().manual_seed(2)
    y = sensor_effects(x, SensorEffects(p=1.0, acc_gain=0.3), g)
    ratio = (y[..., SL_ACC].norm(dim=1) / x[..., SL_ACC].norm(dim=1).clamp(min=1e-6)).numpy()
    assert ratio.min() > 0.69 and ratio.max() < 1.31 and ratio.std() > 0.05
    # the gain's centre moves it as a whole: 0.75 x [0.7, 1.3]; alone it scales every window the same
    y = sensor_effects(x, SensorEffects(p=1.0, acc_gain=0.3, acc_scale=0.75), g)
    ratio = (y[..., SL_ACC].norm(dim=1) / x[..., SL_ACC].norm(dim=1).clamp(min=1e-6)).numpy()
    assert ratio.min() > 0.75 * 0.69 and ratio.max() < 0.75 * 1.31 and ratio.mean() < 0.85
    y = sensor_effects(x, SensorEffects(p=1.0, acc_scale=0.5), g)
    assert torch.allclose(y[..., SL_ACC], 0.5 * x[..., SL_ACC], atol=1e-5)
    assert torch.allclose(y[..., SL_ROT], x[..., SL_ROT], atol=1e-5)
    y = sensor_effects(x, SensorEffects(p=1.0, lag_frames=1.0), g)
    d = (y - x)[:, 5:-5, SL_ACC].abs().max().item()
    assert 0.0 < d < (x[:, 1:, SL_ACC] - x[:, :-1, SL_ACC]).abs().max().item() + 1e-4  # within one frame's step


def test_the_config_round_trips_through_a_dict():
    cfg = TrainConfig.from_dict({"sensor_effects": {"p": 0.8, "mount_deg": 8.0, "lag_frames": 0.5}})
    assert cfg.sensor_effects == SensorEffects(p=0.8, mount_deg=8.0, lag_frames=0.5)
    assert TrainConfig.from_dict(cfg.to_dict()).sensor_effects.mount_deg == 8.0
    assert math.isclose(TrainConfig().sensor_effects.p, 0.0)
