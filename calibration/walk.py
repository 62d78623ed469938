"""Calibration without a table: N-pose, a few steps forward, stand still.

Sensors that do not share a heading reference (each BNO08x, a DualSense, an MTi without
magnetometer) cannot be put in one world frame by the T-pose alone: in a still pose one
known bone orientation fixes the product R_WG R_GS R_SB, and a turn of a sensor's
reference frame about the vertical cannot be told from a turn of its strap. Motion-capture
suits resolve it by walking: every point of the body travels the same few metres forward,
so each sensor's own displacement, measured in its own reference frame, says where
"forward" is for that sensor.

1. ``npose``: stand still, arms by the side (``inference.body.npose_rotations``), ~3 s.
   Gravity fixes each sensor's tilt; the mean free acceleration is the bias removed later.
2. ``walk``: a few steps straight forward (3-5 m), then
3. ``stand``: stand still again (~1.5 s). Velocity is zero at both ends, so integrating
   the free acceleration over the walk and removing the linear drift that makes the end
   velocity zero (a constant bias's signature) gives the velocity, and its integral the
   displacement d_G of that sensor in its reference frame G. The sensor's heading
   correction turns d_G onto +X: R_WG = Rz(-atan2(d_y, d_x)).
4. Sensor-to-bone from the N-pose with that R_WG: R_SB = (R_WG R_GS)^T R_WB_npose.

The heading's spread over the walk's thirds is reported: a walk that curves or a sensor
whose heading drifts shows there (``calibration.quality``).

Thighs and shanks have a second witness that needs no acceleration: in gait they swing
about the body's left-right axis, fastest when the lower end swings forward, so the
horizontal part of their peak angular velocity points to the subject's right. A sensor
whose orientation comes from an on-board AHRS during fast swings (a DualSense on a shank)
leaks gravity into its free acceleration and walks a crooked path; its swing axis stays
right. For those segments the estimate whose thirds agree better is taken.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.body import npose_rotations
from inference.body.rotations import matrix_about_axis, quat_to_matrix
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX, parse_sites

from .core import (
    Calibration,
    CalibrationError,
    StillnessLimits,
    _check,
    _free_acc_G,
    _rms_about,
    mean_rotation,
    stillness,
)

MIN_WALK_M = 1.0  # shorter than this and a bias of 0.05 m/s^2 is a few degrees of heading


@dataclass
class WalkWindows:
    """Frame ranges of one walk calibration in the arrays given (half-open)."""

    npose: tuple[int, int]
    walk: tuple[int, int]
    stand: tuple[int, int]

    def __post_init__(self) -> None:
        a, b, c = self.npose, self.walk, self.stand
        if not (0 <= a[0] < a[1] <= b[0] < b[1] <= c[0] < c[1]):
            raise ValueError(f"walk calibration windows out of order: {self}")


@dataclass
class WalkResult:
    """What the walk measured per sensor, for the quality report."""

    sites: tuple[str, ...]
    heading_rad: np.ndarray  # (S,) the heading correction applied (R_WG = Rz(heading))
    path_m: np.ndarray  # (S,) horizontal displacement over the walk
    spread_deg: np.ndarray  # (S,) largest difference of a third's heading from the whole
    extra: dict = field(default_factory=dict)


def _rz(angle: np.ndarray) -> np.ndarray:
    angle = np.asarray(angle, float)
    return matrix_about_axis(np.broadcast_to([0.0, 0.0, 1.0], angle.shape + (3,)), angle)


def _velocity(a: np.ndarray, fps: float) -> np.ndarray:
    """(T,3) velocity from acceleration with v(0) = v(end) = 0: the drift a constant bias
    adds is linear in time, and removing the line through the end value removes it."""
    v = np.cumsum(a, axis=0) / fps
    ramp = np.linspace(0.0, 1.0, len(v))[:, None]
    return v - ramp * v[-1]


MIN_PRESENT = 0.5  # of the walk's frames, per sensor


def _fill_gaps(a: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(T,3) with the frames not ``ok`` interpolated linearly in time from their neighbours.
    A busy hub marks bursts of frames missing: counting them as zero acceleration shortens
    the velocity along the step phases they fall in and turns the heading (10 % of frames
    missing in bursts put a wrist 4 deg off, 20 % over 9 deg); interpolated, a burst of a few
    frames costs only the acceleration's detail within it."""
    if ok.all():
        return a
    t = np.arange(len(a))
    return np.stack([np.interp(t, t[ok], a[ok, j]) for j in range(a.shape[1])], axis=-1)


def walk_displacements(quat: np.ndarray, free_acc: np.ndarray | None, acc: np.ndarray | None,
                       present: np.ndarray, fps: float, windows: WalkWindows) -> tuple[np.ndarray, np.ndarray]:
    """Per sensor, the horizontal displacement over the walk in its own reference frame
    (S,2), and the mean horizontal velocity of each third of the walk (S,3,2), over the
    frames moving faster than 0.3 m/s."""
    a_G = _free_acc_G(quat, free_acc, acc)
    S = quat.shape[1]
    n0, n1 = windows.npose
    w0, w1 = windows.npose[1], windows.stand[0]
    disp = np.full((S, 2), np.nan)
    thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        ok_still = present[n0:n1, k] & np.all(np.isfinite(a_G[n0:n1, k]), -1)
        seg = a_G[w0:w1, k]
        ok = present[w0:w1, k] & np.all(np.isfinite(seg), -1)
        if ok_still.sum() < 2 or ok.mean() < MIN_PRESENT:
            continue
        bias = a_G[n0:n1, k][ok_still].mean(0)
        a = _fill_gaps(seg - bias, ok)
        v = _velocity(a, fps)[:, :2]
        disp[k] = v.sum(0) / fps
        moving = v[np.linalg.norm(v, axis=-1) > 0.3]  # the still ends say nothing of direction
        if len(moving) >= 3:
            for j, part in enumerate(np.array_split(moving, 3)):
                thirds[k, j] = part.mean(0)
    return disp, thirds


SWING_SEGMENTS = ("l_thigh", "r_thigh", "l_shank", "r_shank")


def swing_forward(quat: np.ndarray, present: np.ndarray, fps: float, window: tuple[int, int]) -> tuple[
        np.ndarray, np.ndarray]:
    """Per sensor, the forward direction (S,2) in its reference frame from its swing axis,
    and the same from each third of the walk (S,3,2): the mean of the fastest tenth of
    the horizontal angular velocities, turned from "right" to "forward" (z cross it)."""
    from inference.body.rotations import so3_log

    a, b = window
    S = quat.shape[1]
    fwd = np.full((S, 2), np.nan)
    thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        ok = present[a:b, k] & np.all(np.isfinite(quat[a:b, k]), -1)
        if ok.mean() < MIN_PRESENT:
            continue
        R = quat_to_matrix(np.where(ok[:, None], quat[a:b, k], [1.0, 0, 0, 0]))
        w = so3_log(R[1:] @ np.swapaxes(R[:-1], -1, -2))[:, :2] * fps  # world-frame rate, horizontal
        w = w[ok[1:] & ok[:-1]]
        if len(w) < 30:
            continue

        def peak_dir(v: np.ndarray) -> np.ndarray:
            mag = np.linalg.norm(v, axis=-1)
            top = v[mag >= np.quantile(mag, 0.9)]
            right = top.mean(0)
            return np.array([-right[1], right[0]])  # z x right = forward

        fwd[k] = peak_dir(w)
        for j, part in enumerate(np.array_split(w, 3)):
            thirds[k, j] = peak_dir(part)
    return fwd, thirds


def _angle_between_2d(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    dot = np.sum(u * v, -1)
    return np.abs(np.rad2deg(np.arctan2(cross, dot)))


def calibrate_walk(
    sites: Sequence[str],
    quat: np.ndarray,
    windows: WalkWindows,
    free_acc: np.ndarray | None = None,
    acc: np.ndarray | None = None,
    gyro: np.ndarray | None = None,
    present: np.ndarray | None = None,
    fps: float = 60.0,
    limits: StillnessLimits | None = None,
    R_WB_npose: np.ndarray | None = None,
) -> tuple[Calibration, WalkResult]:
    """Calibration from an N-pose, a walk forward and a still stand (module docstring).
    Arrays (T,S,...) cover at least the three windows. Raises CalibrationError when the
    subject moved in the N-pose or the walk was too short to find a heading."""
    sites = tuple(parse_sites(list(sites)))
    limits = limits or StillnessLimits()
    quat = np.asarray(quat, dtype=np.float64)
    T, S = quat.shape[:2]
    if windows.stand[1] > T:
        raise CalibrationError(f"walk calibration: the windows end at frame {windows.stand[1]}, the data at {T}")
    ok = np.all(np.isfinite(quat), axis=-1)
    if present is not None:
        ok &= np.asarray(present, bool)
    n0, n1 = windows.npose
    sl = slice(n0, n1)

    def part(x: np.ndarray | None) -> np.ndarray | None:
        return None if x is None else np.asarray(x, float)[sl]

    st = stillness(sites, quat[sl], part(free_acc), part(acc), part(gyro), ok[sl], limits)
    valid = _check("N-pose", st, limits, False, "Stand still, arms by the side, and calibrate again.")
    disp, thirds = walk_displacements(quat, free_acc, acc, ok, fps, windows)
    path = np.linalg.norm(disp, axis=-1)
    short = [s for k, s in enumerate(sites) if valid[k] and not path[k] >= MIN_WALK_M]
    if short and len(short) == int(valid.sum()):
        raise CalibrationError(
            f"walk: the sensors moved {np.nanmax(path) if np.isfinite(path).any() else 0:.1f} m at most "
            f"(at least {MIN_WALK_M:g} m needed); walk 4-6 steps straight forward, then stand still")
    valid &= path >= MIN_WALK_M
    direction = disp.copy()
    spread = np.nanmax(_angle_between_2d(thirds, disp[:, None, :]), axis=1)
    swing, swing_thirds = swing_forward(quat, ok, fps, (windows.npose[1], windows.stand[0]))
    source = ["displacement"] * S
    for k, s in enumerate(sites):
        if s not in SWING_SEGMENTS or not np.isfinite(swing[k]).all():
            continue
        sw_spread = float(np.nanmax(_angle_between_2d(swing_thirds[k], swing[k][None])))
        if not spread[k] <= sw_spread:  # the swing's thirds agree better (or the walk gave nothing)
            direction[k], spread[k], source[k] = swing[k], sw_spread, "swing"
            valid[k] |= bool(st.still[k])
    heading = -np.arctan2(direction[:, 1], direction[:, 0])
    heading[~valid] = 0.0
    R_WG = _rz(heading)
    R_GS = np.where(ok[sl][..., None, None], quat_to_matrix(np.where(ok[sl][..., None], quat[sl], [1.0, 0, 0, 0])),
                    np.nan)
    Rm = mean_rotation(R_GS)
    rest = npose_rotations(1)[0] if R_WB_npose is None else np.asarray(R_WB_npose, float)
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in sites]
    R_SB = np.tile(np.eye(3), (S, 1, 1))
    R_SB[valid] = np.swapaxes(R_WG[valid] @ Rm[valid], -1, -2) @ rest[seg][valid]
    a_G = _free_acc_G(quat[sl], part(free_acc), part(acc))
    a_W = (R_WG[None] @ a_G[..., None])[..., 0]
    a_W[~ok[sl]] = np.nan
    with np.errstate(invalid="ignore"):
        offset = np.nan_to_num(np.nanmean(a_W, axis=0)) if len(a_W) else np.zeros((S, 3))
    offset[~valid] = 0.0
    resid = _rms_about(R_GS, Rm)
    resid[~valid] = np.nan
    cal = Calibration(sites=sites, R_WG=R_WG, R_SB=R_SB, acc_offset=offset, valid=valid, R_known=np.eye(3),
                      residual_world_deg=resid, residual_tpose_deg=resid)
    return cal, WalkResult(sites, heading, path, spread, {"npose_stillness": st, "heading_source": source})
