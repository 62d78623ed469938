"""The IMU reading a tracked pose implies, so that the rest of the chain (hub, calibration,
resampler, model) reads a VR headset or controller as it reads an IMU at that site.

Per site, a short causal window of the last poses (``WINDOW_S`` = 150 ms, at least
``MIN_SAMPLES`` of them) gives:

- ``free_acc`` (world, Z up, gravity removed, m/s^2): twice the quadratic coefficient of a
  least-squares fit of position against time, per axis. Why a fit and not a second
  difference: the tracking jitter (1 mm per axis, white) makes a second difference at
  72 Hz ~13 m/s^2 per axis of noise; a quadratic through the 12 poses of 150 ms (the
  window reaches back to the first pose at or before its start) brings it to ~0.3 m/s^2
  per axis (~0.5 in 3D). Why 150 ms and not the 80 ms first tried (1.1 per axis, ~2 in
  3D): the guided calibration reads a free-acceleration spread above 1 m/s^2 over 0.5 s
  as walking (``calibration/guided.py``), so with 80 ms a standing subject's controllers
  kept the walk step from ever ending. The fit uses the sender's times (``/VMC/Ext/T``)
  when the bundle has them, else arrival times, so an uneven arrival (bundles read in one
  wake-up share one arrival stamp) does not bend the curve; poses at one time are merged
  by the fit, not divided by a zero interval. The price: the estimate is that of the
  window's middle, ~75 ms behind the pose it is sent with (the live resampler's
  11-frame average spans 183 ms).
- ``acc`` (sensor frame, specific force, m/s^2): ``R^T (free_acc + g up)``, what an
  accelerometer strapped to the device reads (a still device reads +9.81 on its up axis,
  as ``drivers.base.Sample`` says of every driver).
- ``gyro`` (sensor frame, rad/s): the slope of a line fitted to the rotation vectors of
  the window's orientations relative to the newest one, ``log(q_new^-1 q_i)``, against
  time: the body-frame angular velocity, averaged over the window for the same reason
  (0.3 deg of orientation jitter per axis: ~5 deg/s per axis instead of ~30 from two
  consecutive poses).

A gap longer than ``MAX_GAP_S`` (a lost tracking, a bridge that stalled) starts the
window over: nothing is implied across it. Until a window holds ``MIN_SAMPLES`` poses
spanning ``MIN_SPAN_S``, the channels are None (the pipeline takes the site as unobserved).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .._math import G, quat_conjugate, quat_log, quat_mul, quat_to_matrix

WINDOW_S = 0.15  # s of poses per fit: with the one before it, 12 poses at 72 Hz
MIN_SAMPLES = 4
MIN_SPAN_S = 0.03  # s the window's times must span (4 bundles at 120 Hz do)
MAX_GAP_S = 0.1  # s between two poses beyond which the window starts over


@dataclass(frozen=True, slots=True)
class ImuReading:
    free_acc: np.ndarray  # (3,) world, m/s^2, gravity removed
    acc: np.ndarray  # (3,) sensor frame, m/s^2, specific force
    gyro: np.ndarray  # (3,) sensor frame, rad/s


class ImpliedImu:
    """One site's window of poses; ``update`` takes the newest and returns the reading it
    implies, or None while the window is too short."""

    def __init__(self, window_s: float = WINDOW_S, min_samples: int = MIN_SAMPLES,
                 max_gap_s: float = MAX_GAP_S) -> None:
        self.window_s, self.min_samples, self.max_gap_s = window_s, min_samples, max_gap_s
        self._t: deque[float] = deque()
        self._p: deque[np.ndarray] = deque()
        self._q: deque[np.ndarray] = deque()

    def reset(self) -> None:
        self._t.clear()
        self._p.clear()
        self._q.clear()

    def update(self, t: float, position: np.ndarray, quat: np.ndarray) -> ImuReading | None:
        if self._t and (t - self._t[-1] > self.max_gap_s or t < self._t[-1] - self.max_gap_s):
            self.reset()  # a gap, or a sender that restarted its clock
        self._t.append(float(t))
        self._p.append(np.asarray(position, float))
        self._q.append(np.asarray(quat, float))
        # keep the newest pose and everything within the window before it, plus one older
        # pose so that the window reaches back the whole WINDOW_S
        while len(self._t) > self.min_samples and self._t[1] <= t - self.window_s:
            self._t.popleft()
            self._p.popleft()
            self._q.popleft()
        n = len(self._t)
        ts = np.fromiter(self._t, float, n) - t
        if n < self.min_samples or ts[-1] - ts[0] < MIN_SPAN_S:
            return None
        # quadratic per axis: columns 1, t, t^2 on times relative to the newest (well conditioned)
        P = np.stack(self._p)
        A = np.stack([np.ones(n), ts, ts * ts], axis=-1)
        if np.linalg.matrix_rank(A) < 3:
            return None
        coef, *_ = np.linalg.lstsq(A, P, rcond=None)
        free = 2.0 * coef[2]
        Q = np.stack(self._q)
        rv = quat_log(quat_mul(quat_conjugate(Q[-1]), Q))  # body-frame rotation of each pose from the newest
        tc = ts - ts.mean()
        gyro = (tc @ (rv - rv.mean(axis=0))) / float(tc @ tc)
        R = quat_to_matrix(Q[-1])
        acc = R.T @ (free + np.array([0.0, 0.0, G]))
        return ImuReading(free, acc, gyro)

