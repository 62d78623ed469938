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
right. For those segments the estimate whose thirds agree better is taken. Both witnesses
live in ``calibration.gait_heading``, which ``imucap import`` uses on logged walks too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.body import npose_rotations
from inference.body.conventions import heading_of, rot_z
from inference.body.rotations import quat_to_matrix
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
from .gait_heading import MIN_WALK_M, pick_direction, swing_forward, walk_displacements


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
    walk = (windows.npose[1], windows.stand[0])
    disp, thirds = walk_displacements(_free_acc_G(quat, free_acc, acc), ok, fps, walk, windows.npose)
    path = np.linalg.norm(disp, axis=-1)
    short = [s for k, s in enumerate(sites) if valid[k] and not path[k] >= MIN_WALK_M]
    if short and len(short) == int(valid.sum()):
        raise CalibrationError(
            f"walk: the sensors moved {np.nanmax(path) if np.isfinite(path).any() else 0:.1f} m at most "
            f"(at least {MIN_WALK_M:g} m needed); walk 4-6 steps straight forward, then stand still")
    valid &= path >= MIN_WALK_M
    swing, swing_thirds = swing_forward(quat, ok, fps, walk)
    direction, spread, source = pick_direction(sites, disp, disp_thirds=thirds, swing=swing, swing_thirds=swing_thirds)
    for k in range(S):
        if source[k] != "displacement":
            valid[k] |= bool(st.still[k])
    heading = -heading_of(direction)
    heading[~valid] = 0.0
    R_WG = rot_z(heading)
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
