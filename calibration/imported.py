"""Calibration of a logged session from another system: a still stand, then whatever the
subject did, with each sensor's heading from the gait when the log holds walking.

Why: the standing calibration (``calibration.standing``) assumes that every sensor's
reference frame shares one heading. A sensor whose magnetometer was disturbed, or a
6-axis sensor, breaks that silently: on a real MT Manager session one shank sensor was
45-50 deg off the others while the stand's residuals were all under 1.5 deg. Walking
tells each sensor's heading (``calibration.gait_heading``: the swing axis of thighs and
shanks, every sensor's displacement between still moments), so:

- ``standing``: one heading for all (the knees' flexion, else the shanks' swing); sensors
  whose gait disagrees are named, not corrected;
- ``walk``: each sensor that the gait gives a heading for gets its own; the others take
  the heading most sensors agree on, and the report says so;
- ``auto``: ``walk`` when the log holds walking (a leg segment swings at least 4 times
  past 90 deg/s), else ``standing``.

Warnings are one line each and start with the site they are about (the contract of
``imucap import --json``'s ``calibration.warnings``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.conventions import turn_xy
from inference.body.rotations import matrix_about_axis, matrix_to_quat, quat_multiply
from inference.body.skeleton import parse_sites

from .core import Calibration, CalibrationError
from .gait_heading import WARN_DEG, GaitHeadings, consensus_forward, gait_headings, signed_angle_deg
from .heading import forward_from_motion
from .standing import calibrate_standing, still_stand

MODES = ("standing", "walk", "auto")


@dataclass
class LogCalibration:
    """A log's calibration and what the report says of it."""

    calibration: Calibration
    method: str  # "walk" or "standing"
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # about the whole log, not one site
    headings: dict[str, dict] = field(default_factory=dict)  # site -> offset_deg, source, corrected
    gait: GaitHeadings | None = None


def calibrate_log(sites: Sequence[str], quat: np.ndarray, rate: np.ndarray, present: np.ndarray, fps: float,
                  mode: str = "auto", acc: np.ndarray | None = None,
                  free_acc: np.ndarray | None = None, name: str = "the log") -> LogCalibration:
    """Calibrate a log that starts with a still stand (module docstring). quat (T,S,4)
    R_GS, rate (T,S,3) rad/s in the sensor frame (the gyro, or the rate from orientation),
    acc (T,S,3) specific force, present (T,S)."""
    if mode not in MODES:
        raise ValueError(f"unknown calibration {mode!r} (known: {', '.join(MODES)})")
    sites = tuple(parse_sites(list(sites)))
    quat = np.asarray(quat, float)
    present = np.asarray(present, bool)
    still = still_stand(rate, present, fps, name=name)
    gait = gait_headings(sites, quat, rate, present, fps, still, free_acc=free_acc, acc=acc)
    notes: list[str] = []
    method = mode
    if mode == "auto":
        method = "walk" if gait.walking else "standing"
        if not gait.walking:
            notes.append(f"no walking in the log ({gait.steps} leg swings past 90 deg/s, 4 needed): one heading "
                         "for all sensors (standing)")
    elif mode == "walk" and not gait.walking:
        raise CalibrationError(f"--calibration walk: the log holds no walking ({gait.steps} leg swings past 90 "
                               "deg/s, at least 4 needed); use --calibration standing")
    shared = consensus_forward(gait.forward)
    if shared is None:
        shared_q = quat
    else:  # every sensor the gait spoke for turned into the frame most agree on, so the knees see one frame
        off = np.where(np.all(np.isfinite(gait.forward), -1) & (method == "walk"),
                       np.arctan2(gait.forward[:, 1], gait.forward[:, 0]) - np.arctan2(shared[1], shared[0]), 0.0)
        into_shared = matrix_to_quat(matrix_about_axis(np.tile([0.0, 0.0, 1.0], (len(off), 1)), -off))
        shared_q = quat_multiply(into_shared[None], quat)
    try:
        forward, forward_from = forward_from_motion(sites, shared_q, rate, present, still)
    except CalibrationError:
        if method == "standing" or shared is None:
            raise
        forward, forward_from = np.array([shared[0], shared[1], 0.0]), "gait (the heading most sensors agree on)"
    if shared is None:
        shared = forward[:2]
    base = float(np.arctan2(forward[1], forward[0]) - np.arctan2(shared[1], shared[0]))
    warnings: list[str] = []
    headings: dict[str, dict] = {}
    own = np.full((len(sites), 2), np.nan)
    for k, s in enumerate(sites):
        f = gait.forward[k]
        if not np.isfinite(f).all():
            headings[s] = {"offset_deg": None, "source": gait.source[k], "corrected": False}
            if method == "walk":
                warnings.append(f"{s}: keeps the shared heading ({gait.source[k]})")
            continue
        off = float(signed_angle_deg(np.asarray(shared), f))  # this sensor's frame turned from the others'
        corrected = method == "walk"
        if corrected:  # its own forward, turned as the knees turned the shared one
            own[k] = turn_xy(f[:2], base)
        headings[s] = {"offset_deg": round(off, 1), "source": gait.source[k], "corrected": corrected}
        if abs(off) > WARN_DEG:
            what = "corrected" if corrected else "not corrected (--calibration standing; walk corrects it)"
            warnings.append(f"{s}: heading {abs(off):.0f} deg off the others ({gait.source[k]}); {what}")
    cal = calibrate_standing(sites, quat, acc=acc, free_acc=free_acc, gyro=rate, present=present, still=still,
                             rate=fps, forward_G=forward, sensor_forward_G=own if method == "walk" else None)
    cal.meta.update(method=method, forward_from=forward_from, warnings=warnings)
    return LogCalibration(cal, method, warnings, notes, headings, gait)


__all__ = ["LogCalibration", "MODES", "calibrate_log"]
