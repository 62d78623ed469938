"""What a real log's subject is doing, frame by frame, from its sensors' orientations alone:
straight walking, turning, standing or something else (``classify_phases``).

The yardstick (``app/evaluation/real.py``) splits each left-out segment's error by phase, so
that a figure says whether the model fails on the walk itself, in the turns or while the
subject stands. Nothing here needs a calibration: angular speeds and the rate of turn about
the vertical do not change with how a sensor sits on its segment (a constant mounting
rotation on the right of R_WS) or with its heading (a constant turn about Z on the left).

- **standing**: every sensor turns slower than ``STILL_RAD_S`` throughout a ``STILL_WINDOW_S``
  window round the frame, for at least ``STAND_MIN_S`` in a row;
- **turning**: the body's rate of turn about the vertical (pelvis, else torso, else the mean
  over the sensors), averaged over ``TURN_WINDOW_S`` (about a stride, so that the pelvis'
  own swing in each step cancels), is above ``TURN_RAD_S``;
- **walking**: not turning, and both legs swing (a leg sensor, shank first, then thigh, then
  foot, turns faster than ``SWING_RAD_S`` at some moment) within ``GAIT_WINDOW_S`` round the
  frame: gait cycles of both legs;
- **other**: the rest (a knee lift, a step on the spot, the moments between).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.ndimage import maximum_filter1d, uniform_filter1d

from inference.body.rotations import matrix_angle_between

PHASES: tuple[str, ...] = ("walking", "turning", "standing", "other")
STILL_RAD_S = 0.35  # 20 deg/s: postural sway and a fusion's wobble stay below, a step does not
STILL_WINDOW_S = 0.5
STAND_MIN_S = 1.0
TURN_RAD_S = 0.35  # 20 deg/s averaged over a stride: a curve of 3.4 m radius at 1.2 m/s, or a turn on the spot
TURN_WINDOW_S = 1.2
SWING_RAD_S = 1.5  # a shank swings at 3-6 rad/s in a walk's swing phase
GAIT_WINDOW_S = 1.5
_LEG_ORDER = ("shank", "thigh", "foot")


def world_rates(R: np.ndarray, fps: float) -> np.ndarray:
    """(T, 3) angular velocity in the world frame (rad/s) of orientations R (T, 3, 3), central
    differences (one-sided at the ends); NaN where R is."""
    R = np.asarray(R, dtype=float)
    T = len(R)
    out = np.full((T, 3), np.nan)
    if T < 2:
        return out
    # ω^ = dR R^T / dt over one frame, read off the skew part of R_{t+1} R_t^T
    D = R[1:] @ np.swapaxes(R[:-1], -1, -2)
    w = np.stack([D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0], D[:, 1, 0] - D[:, 0, 1]], axis=-1) / 2.0
    ang = matrix_angle_between(R[1:], R[:-1])
    s = np.linalg.norm(w, axis=-1)
    scale = np.where(s > 1e-12, ang / np.maximum(s, 1e-12), 1.0)
    step = w * scale[:, None] * fps  # (T-1, 3) at the midpoints
    out[1:-1] = (step[1:] + step[:-1]) / 2.0
    out[0], out[-1] = step[0], step[-1]
    return out


def quat_matrices(quat: np.ndarray) -> np.ndarray:
    """(..., 3, 3) R of (w, x, y, z) quaternions, NaN where a quaternion is not finite (a
    sensor that did not deliver)."""
    from inference.body.conventions import quat_to_matrix

    q = np.asarray(quat, dtype=float)
    ok = np.all(np.isfinite(q), axis=-1) & (np.linalg.norm(np.nan_to_num(q), axis=-1) > 1e-9)
    R = quat_to_matrix(np.where(ok[..., None], q, np.array([1.0, 0.0, 0.0, 0.0])))
    return np.where(ok[..., None, None], R, np.nan)


def _nanfill(x: np.ndarray, value: float) -> np.ndarray:
    return np.where(np.isfinite(x), x, value)


def _runs_at_least(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` with its True runs shorter than ``n`` frames set False."""
    out = mask.copy()
    i, T = 0, len(mask)
    while i < T:
        if mask[i]:
            j = i
            while j < T and mask[j]:
                j += 1
            if j - i < n:
                out[i:j] = False
            i = j
        else:
            i += 1
    return out


def _leg_sites(sites: list[str]) -> dict[str, str] | None:
    """{side: the leg sensor that tells its swing} when both legs have one (shank first)."""
    for seg in _LEG_ORDER:
        if f"l_{seg}" in sites and f"r_{seg}" in sites:
            return {"l": f"l_{seg}", "r": f"r_{seg}"}
    return None


def classify_phases(orientations: Mapping[str, np.ndarray], fps: float) -> np.ndarray:
    """(T,) one of ``PHASES`` per frame, from world orientations (site -> (T, 3, 3), NaN where
    a sensor did not deliver) sampled at ``fps`` (module docstring for the rules)."""
    sites = list(orientations)
    if not sites:
        raise ValueError("classify_phases needs at least one sensor")
    rates = {s: world_rates(orientations[s], fps) for s in sites}
    T = len(next(iter(rates.values())))
    win = lambda sec: max(1, int(round(sec * fps)))  # noqa: E731

    speed = np.stack([np.linalg.norm(_nanfill(rates[s], 0.0), axis=-1) for s in sites])  # (S, T)
    fast = maximum_filter1d(speed.max(axis=0), win(STILL_WINDOW_S), mode="nearest")
    standing = _runs_at_least(fast < STILL_RAD_S, win(STAND_MIN_S))

    body = next((s for s in ("pelvis", "torso") if s in rates), None)
    yaw = rates[body][:, 2] if body else np.nanmean(np.stack([rates[s][:, 2] for s in sites]), axis=0)
    turn_rate = uniform_filter1d(_nanfill(yaw, 0.0), win(TURN_WINDOW_S), mode="nearest")
    turning = (np.abs(turn_rate) > TURN_RAD_S) & ~standing

    legs = _leg_sites(sites)
    if legs is None:
        walking = np.zeros(T, bool)
    else:
        swing = [maximum_filter1d(np.linalg.norm(_nanfill(rates[legs[k]], 0.0), axis=-1), win(GAIT_WINDOW_S),
                                  mode="nearest") > SWING_RAD_S for k in ("l", "r")]
        walking = swing[0] & swing[1] & ~turning & ~standing

    out = np.full(T, "other", dtype=object)
    out[walking] = "walking"
    out[turning] = "turning"
    out[standing] = "standing"
    return out.astype(str)


def phase_seconds(labels: np.ndarray, fps: float) -> dict[str, float]:
    """Seconds per phase (every phase named, 0 when absent)."""
    return {p: round(float(np.sum(labels == p)) / fps, 2) for p in PHASES}


__all__ = ["PHASES", "classify_phases", "phase_seconds", "quat_matrices", "world_rates"]
