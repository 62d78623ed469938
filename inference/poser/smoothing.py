"""Causal, speed-adaptive low-passes for the live poser's outputs (root, orientations).

Every 20 Hz frame of the live poser is a fresh inference, so the root's height and its
per-frame displacement (and, without insoles, the contact-driven root correction) wobble
by millimetres from frame to frame, and so do the orientations no sensor measures.
Measured on HDM05 dg (6 sites, docs/model.md, "Output filters and joint constraints") the root wobble was most of the
jitter ratio of an early model (3.64; 2.05 with the true root path); the model
trained to weight the last frame is more accurate but wobbles more in orientation too.
A fixed low-pass would trade the wobble for lag in fast motion; the 1-Euro filter
(Casiez, Roussel and Vogel, CHI 2012) lowers its cutoff when the signal is slow and
raises it when fast, which is what a live viewer wants: a still body stays still and a
jump is not delayed much. On rotations it moves along the geodesic; measured segments
pass through untouched (their orientation is the measurement).

The filters run on numpy (the live poser's per-frame path, ``rotations``' ``*_np`` kernels); a
torch tensor in gives a tensor out, computed the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from inference.body.rotations import matrix_to_quat_np, quat_power_np, quat_to_matrix_np


@dataclass(frozen=True)
class OneEuroConfig:
    """Cutoffs in Hz; beta in Hz per (unit of the signal)/s of its filtered speed."""

    min_cutoff_hz: float = 2.0
    beta: float = 0.5
    rate_cutoff_hz: float = 1.0


# chosen by sweeps on the HDM05 dg subset (docs/model.md, "Output filters and joint
# constraints"). Root: 2 Hz at rest (time constant 80 ms), ~2.7 Hz at a walk (1.3 m/s):
# jitter 3.64 -> 2.38, RE2 unchanged. Unmeasured orientations: 4 Hz at rest (40 ms), beta
# per rad/s: jitter 3.55 -> 2.97 for +0.2 deg GA with an early model.
ROOT_SMOOTHING = OneEuroConfig(min_cutoff_hz=2.0, beta=0.5)
ROTATION_SMOOTHING = OneEuroConfig(min_cutoff_hz=4.0, beta=0.3)


def smoothing_gain(cutoff_hz: np.ndarray | float, dt: float) -> np.ndarray:
    """Gain of a first-order low-pass with this cutoff sampled every dt seconds."""
    tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz))
    return 1.0 / (1.0 + tau / dt)


class _OneEuro:
    """State and gains shared by the filters: the last output and the filtered speed."""

    def __init__(self, fps: float, config: OneEuroConfig | None = None) -> None:
        self.dt = 1.0 / float(fps)
        self.config = config or OneEuroConfig()
        self._rate_gain = float(smoothing_gain(self.config.rate_cutoff_hz, self.dt))
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next sample passes through and starts the state."""
        self._last: np.ndarray | None = None
        self._rate: np.ndarray | None = None

    def _gain(self, speed: np.ndarray) -> np.ndarray:
        """Update the filtered speed with this sample's and return the smoothing gain."""
        assert self._rate is not None
        self._rate = self._rate + self._rate_gain * (speed - self._rate)
        return smoothing_gain(self.config.min_cutoff_hz + self.config.beta * self._rate, self.dt)

    def _start(self, x: np.ndarray, rows: tuple[int, ...]) -> np.ndarray:
        self._last = x.copy()
        self._rate = np.zeros(rows, dtype=x.dtype)
        return x.copy()


def _speed(step: np.ndarray, dt: float) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", step, step)) / dt


class VectorOneEuro(_OneEuro):
    """1-Euro filter of a vector signal (..., D): each row's cutoff follows its speed."""

    def __call__(self, x: np.ndarray | Tensor) -> np.ndarray | Tensor:
        if isinstance(x, Tensor):
            return torch.from_numpy(self(x.numpy()))
        if self._last is None:
            return self._start(x, tuple(x.shape[:-1]))
        step = x - self._last
        gain = self._gain(_speed(step, self.dt)).astype(x.dtype, copy=False)
        self._last = self._last + gain[..., None] * step
        return self._last.copy()


class RotationOneEuro(_OneEuro):
    """1-Euro filter of rotations (S, 3, 3), one state per rotation; the speed that sets
    each cutoff is the filtered angular rate (rad/s)."""

    def __call__(self, R: np.ndarray | Tensor, passthrough: np.ndarray | Tensor | None = None) -> np.ndarray | Tensor:
        """Filtered R (S, 3, 3); ``passthrough`` (S,) bool: returned as given (and kept
        as the state), for measured segments."""
        if isinstance(R, Tensor):
            keep = passthrough.numpy() if isinstance(passthrough, Tensor) else passthrough
            return torch.from_numpy(self(R.numpy(), keep))
        if self._last is None:
            return self._start(R, (R.shape[0],))
        # the step in each rotation's own frame, q (w >= 0), taken ``gain`` of the way
        q = matrix_to_quat_np(np.swapaxes(self._last, -1, -2) @ R)
        v = q[:, 1:]
        angle = 2.0 * np.arctan2(np.sqrt((v * v).sum(-1)), q[:, 0])
        gain = self._gain(angle / self.dt).astype(R.dtype, copy=False)
        out = self._last @ quat_to_matrix_np(quat_power_np(q, gain))
        if passthrough is not None:
            out = np.where(passthrough[:, None, None], R, out)
        self._last = out
        return out.copy()
