"""An imported log's devices on one 60 Hz grid, as the live hub would have put them."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from drivers.device_log import DeviceLog
from inference.body.rotations import quat_conjugate, quat_multiply, quat_to_axis_angle
from inference.signals.resample import to_grid

from .names import Source

RATE = 60.0
GYRO_WINDOW_S = 0.2  # wide enough that orientation jitter does not read as motion, short against a step


def duplicates(files: Sequence[Path]) -> tuple[list[Path], list[str]]:
    """(the files without byte-identical copies of an earlier one, a warning per copy): one
    sensor's export copied under a second name would import as two sensors moving exactly
    alike, or clash on one site."""
    first: dict[str, Path] = {}
    keep, warnings = [], []
    for f in files:
        h = hashlib.sha256(f.read_bytes()).hexdigest()
        if h in first:
            warnings.append(f"{f}: byte-identical to {first[h]} (one sensor's export twice?); skipped")
            continue
        first[h] = f
        keep.append(f)
    return keep, warnings


def gyro_from_orientation(t: np.ndarray, quat: np.ndarray, window_s: float = GYRO_WINDOW_S) -> np.ndarray:
    """(N, 3) angular rate in the sensor frame (rad/s) from orientations R_GS (N, 4) at
    times t: the least-squares slope of the rotation from each sample to its neighbours
    within ``window_s`` (fewer at the ends). A slope over a window, not a difference of
    two samples, so that orientation jitter does not read as motion."""
    n = len(t)
    h = max(1, int(round(window_s / float(np.median(np.diff(t))) / 2)))
    i = np.arange(n)
    steps = [np.clip(i + j, 0, n - 1) for j in range(-h, h + 1)]
    dt = np.stack([t[k] - t for k in steps])  # (W, N)
    rot = np.stack([quat_to_axis_angle(quat_multiply(quat_conjugate(quat), quat[k])) for k in steps])  # (W, N, 3)
    dt_c = dt - dt.mean(axis=0)
    rot_c = rot - rot.mean(axis=0)
    return np.einsum("wn,wnc->nc", dt_c, rot_c) / np.sum(dt_c**2, axis=0)[:, None]


def check_acc(src: Source) -> Source:
    """The device, refused where its log has no acceleration at all: the model needs it."""
    if not np.isfinite(src.log.acc).any():
        raise ValueError(f"{src.label}: no acceleration columns (Acc_* or FreeAcc_*); export them too")
    return src


def _rate_for_calibration(d: DeviceLog) -> np.ndarray:
    """(N, 3) the device's gyro, or where its log has none, its rate from orientation."""
    return d.gyro if np.isfinite(d.gyro).any() else gyro_from_orientation(d.t, d.quat)


def align_clocks(by_site: dict[str, Source]) -> str:
    """Keep the devices' own times when they share a clock (their spans overlap and no
    header says otherwise); else put each one's first sample at 0. Returns which."""
    logs = [s.log for s in by_site.values()]
    unsynced = any(d.info.get("syncstatus", "").strip().lower().startswith("un") for d in logs)
    if not unsynced and max(d.t[0] for d in logs) < min(d.t[-1] for d in logs):
        return "shared"
    for d in logs:
        d.t = d.t - d.t[0]
    return "aligned at each device's first sample (clocks not shared)"


def on_grid(by_site: dict[str, Source], sites: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, float]:
    """(quat (n,S,4), vectors (n,S,3,3): specific force, gyro as logged and the rate for
    calibration, the grid's first time on the logs' clock) of every device on one RATE
    grid, NaN where a device did not deliver."""
    logs = [by_site[s].log for s in sites]
    t0 = math.ceil(min(float(d.t[0]) for d in logs) * RATE) / RATE
    n = int(math.floor((max(float(d.t[-1]) for d in logs) - t0) * RATE)) + 1
    quat = np.full((n, len(sites), 4), np.nan)
    vec = np.full((n, len(sites), 3, 3), np.nan)
    for k, d in enumerate(logs):
        v = np.stack([d.acc, d.gyro, _rate_for_calibration(d)], axis=1)
        tg, q, v, ok = to_grid(d.t, d.quat, v, fps=RATE, t0=t0)
        idx = np.rint((tg - t0) * RATE).astype(int)
        keep = (idx >= 0) & (idx < n) & ok
        quat[idx[keep], k] = q[keep]
        vec[idx[keep], k] = v[keep]
    return quat, vec, t0




__all__ = ["GYRO_WINDOW_S", "RATE", "align_clocks", "check_acc", "duplicates", "gyro_from_orientation", "on_grid"]
