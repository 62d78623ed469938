"""Calibration from a standing start, for sessions recorded without our protocol.

A log from another system (``drivers.ximu3``: an x-IMU3 GUI log) holds the subject
standing still for a second somewhere (at its start, usually; ``still_stand`` finds it
anywhere), and has no sensors-on-a-table window. Two facts stand in for it:

1. Sensors whose AHRS uses the magnetometer share one Earth frame G (Z up, heading to
   magnetic north), so one yaw, the same for every sensor, turns G into our world W
   (X = the subject's forward). Without a table window the sensors' heading offsets
   cannot be measured, so this *assumes* a shared G; a sensor whose own heading drifted
   (magnetic disturbance) comes out yawed by that much.
2. The forward direction comes from the motion itself: a knee only flexes one way. With
   the bone-down axis of each thigh and shank fixed from the standing window, the
   horizontal part of (shank-down - thigh-down) points backward whenever the knee bends,
   in walking, squatting and climbing alike. Its sum over the session (each frame turned
   back by how far the pelvis has turned since the stand, so a walk back after a turn
   votes the same way) is the subject's backward at calibration. (Functional calibration of this
   kind is how lower-body IMU systems find the sagittal plane without a T-pose.) Without
   a thigh (the paper's six sensors) the shanks' swing says it instead: they turn
   fastest when the foot goes forward. On the real x-IMU3 log the two agree within
   1.1 deg.

Sensor-to-bone then follows as in ``core.calibrate_tpose``, with the standing N-pose as
the rest pose (legs and trunk as in the T-pose, arms by the side).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from inference.body.body import npose_rotations
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import parse_sites

from .core import Calibration, CalibrationError, StillnessLimits, _free_acc_G, calibrate_tpose
from .heading import KNEE_PAIRS, forward_from_knees, forward_from_motion, forward_from_shanks

MIN_STILL_S = 1.0
STILL_GYRO_DEG_S = 10.0


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in a (T,) bool."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def still_stand(gyro: np.ndarray, present: np.ndarray, rate: float, min_seconds: float = MIN_STILL_S,
                max_gyro_deg_s: float = STILL_GYRO_DEG_S, name: str = "the log") -> slice:
    """The first still stand of ``min_seconds`` anywhere in a log: frames where every present
    sensor turns slower than ``max_gyro_deg_s``. A log that starts still gives its whole
    still start, as before; a trial recorded as people record them (the subject already
    walking when the recording starts) gives the stand where it is. gyro (T,S,3) rad/s,
    present (T,S). Raises CalibrationError saying where it looked and what it found."""
    g = np.rad2deg(np.linalg.norm(np.nan_to_num(np.asarray(gyro, dtype=np.float64)), axis=-1))
    still = ~np.any((g > max_gyro_deg_s) & np.asarray(present, bool), axis=1)
    runs = _runs(still)
    for a, b in runs:
        if b - a >= min_seconds * rate:
            return slice(int(a), int(b))
    a, b = max(runs, key=lambda r: r[1] - r[0], default=(0, 0))
    raise CalibrationError(
        f"no still stand of {min_seconds:g} s found in 0-{len(still) / rate:.1f} s of {name} (longest still: "
        f"{(b - a) / rate:.2f} s at {a / rate:.1f} s; every sensor below {max_gyro_deg_s:g} deg/s); record a still "
        "stand, or give a calibration trial that has one")


def calibrate_standing(sites: Sequence[str], quat: np.ndarray, free_acc: np.ndarray | None = None,
                       acc: np.ndarray | None = None, gyro: np.ndarray | None = None,
                       present: np.ndarray | None = None, still: slice | None = None, rate: float = 60.0,
                       forward_G: np.ndarray | None = None, limits: StillnessLimits | None = None,
                       sensor_forward_G: np.ndarray | None = None) -> Calibration:
    """A ``Calibration`` from a session that holds a still stand (module docstring).
    quat (T,S,4) R_GS, free_acc (T,S,3) in G or acc (T,S,3) specific force, gyro (T,S,3),
    present (T,S); ``still`` the standing frames (default ``still_stand``), ``forward_G``
    the subject's forward in G (default from the knees). ``sensor_forward_G`` (S,2+):
    each sensor's own forward in its own frame (``gait_heading``), where its frame does
    not share the others' heading; NaN rows keep ``forward_G``."""
    sites = tuple(parse_sites(list(sites)))
    quat = np.asarray(quat, dtype=np.float64)
    present = np.all(np.isfinite(quat), axis=-1) if present is None else np.asarray(present, bool)
    if still is None:
        if gyro is None:
            raise CalibrationError("standing calibration: without gyro data the still start must be given")
        still = still_stand(gyro, present, rate)
    if forward_G is None:
        f, method = forward_from_motion(sites, quat, gyro, present, still)
    else:
        f, method = np.asarray(forward_G, float), "given"
    yaw = float(np.arctan2(f[1], f[0]))
    S = len(sites)
    yaws = np.full(S, yaw)
    if sensor_forward_G is not None:
        own = np.asarray(sensor_forward_G, float)[:, :2]
        mine = np.all(np.isfinite(own), axis=-1)
        yaws[mine] = np.arctan2(own[mine, 1], own[mine, 0])
    R_WG = matrix_about_axis(np.tile([0.0, 0.0, 1.0], (S, 1)), -yaws)
    win = {k: None if v is None else np.asarray(v, dtype=np.float64)[still]
           for k, v in (("free_acc", free_acc), ("acc", acc), ("gyro", gyro))}
    R_SB, valid, resid = calibrate_tpose(sites, quat[still], R_WG, present=present[still],
                                         R_WB_rest=npose_rotations(1)[0], limits=limits, **win)
    a_W = (R_WG[None] @ _free_acc_G(quat[still], win["free_acc"], win["acc"])[..., None])[..., 0]
    a_W[~present[still]] = np.nan
    with np.errstate(invalid="ignore"):
        offset = np.nan_to_num(np.nanmean(a_W, axis=0))
    offset[~valid] = 0.0
    return Calibration(sites=sites, R_WG=R_WG, R_SB=R_SB, acc_offset=offset, valid=valid, residual_tpose_deg=resid,
                       meta={"method": "standing", "forward_G": [float(x) for x in f], "forward_from": method,
                             "still_frames": still.stop, "still_from": still.start})


__all__ = ["calibrate_standing", "forward_from_knees", "forward_from_shanks", "forward_from_motion", "still_stand",
           "KNEE_PAIRS"]
