"""Calibration from a standing start, for sessions recorded without our protocol.

A log from another system (``drivers.ximu3``: an x-IMU3 GUI log) starts with the subject
standing still, and has no sensors-on-a-table window. Two facts stand in for it:

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
from inference.body.rotations import matrix_about_axis, quat_to_matrix
from inference.body.skeleton import parse_sites

from .core import (
    Calibration,
    CalibrationError,
    StillnessLimits,
    _free_acc_G,
    calibrate_tpose,
    mean_rotation,
)

KNEE_PAIRS = (("l_thigh", "l_shank"), ("r_thigh", "r_shank"))
DOWN = np.array([0.0, 0.0, -1.0])
MIN_BEND_DEG = 20.0  # a knee must bend this far at least once for its plane to count
MIN_SWING_DEG_S = 30.0  # a shank turning slower than this is standing, not swinging
MIN_SWING_SKEW = 0.3  # below it the swing peaks do not stand out: forward and backward look alike


def still_start(gyro: np.ndarray, present: np.ndarray, rate: float, min_seconds: float = 1.0,
                max_gyro_deg_s: float = 10.0) -> slice:
    """The still stretch at the start of a session: frames from the first until any
    present sensor turns faster than ``max_gyro_deg_s``. gyro (T,S,3) rad/s, present
    (T,S). Raises CalibrationError when it is shorter than ``min_seconds``."""
    g = np.rad2deg(np.linalg.norm(np.nan_to_num(np.asarray(gyro, dtype=np.float64)), axis=-1))
    moving = np.any((g > max_gyro_deg_s) & np.asarray(present, bool), axis=1)
    end = int(np.argmax(moving)) if moving.any() else len(moving)
    if end < min_seconds * rate:
        raise CalibrationError(
            f"standing calibration: the session is still for only {end / rate:.2f} s at its start "
            f"(need {min_seconds:g} s with every sensor below {max_gyro_deg_s:g} deg/s); record a still stand first")
    return slice(0, end)


def _still_mean(R: np.ndarray, ok: np.ndarray, still: slice) -> np.ndarray:
    """(3,3) one sensor's mean orientation over the still stand (R (T,3,3), ok (T,))."""
    return mean_rotation(np.where(ok[still][:, None, None], R[still], np.nan)[:, None])[0]


def _heading_change(R: np.ndarray, ok: np.ndarray, still: slice) -> np.ndarray:
    """(T,) how far (rad) one sensor has turned about the vertical since the still stand,
    from its rotation in G since then; NaN where it did not deliver."""
    dR = R @ _still_mean(R, ok, still).T
    yaw = np.arctan2(dR[:, 1, 0] - dR[:, 0, 1], dR[:, 0, 0] + dR[:, 1, 1])
    return np.where(ok, yaw, np.nan)


def _turn_back(v: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N,2) horizontal vectors turned by -yaw: into the heading the subject had when standing."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=1)


def forward_from_knees(sites: Sequence[str], quat: np.ndarray, present: np.ndarray, still: slice) -> np.ndarray:
    """(3,) the subject's forward in the sensors' shared frame G, horizontal, unit, from
    the knees' flexion over the whole session (module docstring). quat (T,S,4) R_GS.

    The subject turns during a session, and a walk back bends the knees the other way in
    G: each frame's vote is turned back by how far the pelvis (else that leg's thigh) has
    turned since the stand, so every frame votes for the forward *at calibration*."""
    sites = list(sites)
    quat = np.asarray(quat, dtype=np.float64)
    ok = np.all(np.isfinite(quat), axis=-1) & np.asarray(present, bool)
    R = quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))
    pelvis = sites.index("pelvis") if "pelvis" in sites and ok[still, sites.index("pelvis")].any() else None
    pelvis_turn = _heading_change(R[:, pelvis], ok[:, pelvis], still) if pelvis is not None else None
    back = np.zeros(3)
    pairs = seen = 0
    for thigh, shank in KNEE_PAIRS:
        if thigh not in sites or shank not in sites:
            continue
        i, j = sites.index(thigh), sites.index(shank)
        both = ok[:, i] & ok[:, j]
        if not both[still].any() or both.sum() < 2:
            continue
        # each bone's down axis in its sensor's frame, from standing
        d_thigh = R[both, i] @ (_still_mean(R[:, i], ok[:, i], still).T @ DOWN)
        d_shank = R[both, j] @ (_still_mean(R[:, j], ok[:, j], still).T @ DOWN)
        bend = d_shank - d_thigh
        turned = (pelvis_turn if pelvis_turn is not None else _heading_change(R[:, i], ok[:, i], still))[both]
        angle = np.degrees(2.0 * np.arcsin(np.clip(np.linalg.norm(bend, axis=1) / 2.0, 0.0, 1.0)))
        # a straight knee's bend is sensor noise in any direction
        bent = (angle > MIN_BEND_DEG / 2) & np.isfinite(turned)
        if angle.max(initial=0.0) >= MIN_BEND_DEG:
            back[:2] += _turn_back(bend[bent, :2], turned[bent]).sum(axis=0)
            pairs += 1
        seen += 1
    if seen == 0:
        raise CalibrationError("standing calibration: the forward direction needs a thigh and a shank sensor of one "
                               "leg; give it another way")
    n = float(np.linalg.norm(back[:2]))
    if pairs == 0 or n < 1e-6:
        raise CalibrationError(f"standing calibration: the knees never bent by {MIN_BEND_DEG:g} deg, so the forward "
                               "direction is unknown; record a few steps or a squat after the still stand")
    return -back / n


def forward_from_shanks(sites: Sequence[str], quat: np.ndarray, gyro: np.ndarray, present: np.ndarray,
                        still: slice) -> np.ndarray:
    """(3,) the subject's forward in G from the shanks' swing, for sensor sets without a
    thigh (the paper's six: pelvis, head, wrists, shanks). A shank turns mostly about the
    knee's axis, and fastest in swing, when the foot goes forward: the main axis of its
    angular velocity (turned back by the pelvis's turn since the stand) is lateral, and
    its sign is the one that makes the swing peaks the large ones (a positive third
    moment). gyro (T,S,3) rad/s in the sensor frame."""
    sites = list(sites)
    quat = np.asarray(quat, dtype=np.float64)
    gyro = np.asarray(gyro, dtype=np.float64)
    ok = np.all(np.isfinite(quat), axis=-1) & np.asarray(present, bool) & np.all(np.isfinite(gyro), axis=-1)
    R = quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))
    p_idx = sites.index("pelvis") if "pelvis" in sites else None
    turned = (_heading_change(R[:, p_idx], ok[:, p_idx], still) if p_idx is not None
              else np.zeros(len(quat)))
    fwd = np.zeros(2)
    used = []
    for s in ("l_shank", "r_shank"):
        if s not in sites:
            continue
        k = sites.index(s)
        use = ok[:, k] & np.isfinite(turned)
        w = _turn_back(np.einsum("tij,tj->ti", R[use, k], gyro[use, k])[:, :2], turned[use])
        w = w[np.linalg.norm(w, axis=1) > np.deg2rad(MIN_SWING_DEG_S)]
        if len(w) < 10:
            continue
        a = np.linalg.eigh(w.T @ w)[1][:, -1]
        p = w @ a
        skew = float(np.mean(p**3) / np.mean(p**2) ** 1.5)
        if abs(skew) < MIN_SWING_SKEW:
            continue
        a = a if skew > 0 else -a
        fwd += np.array([-a[1], a[0]])  # z x a
        used.append(s)
    n = float(np.linalg.norm(fwd))
    if not used or n < 1e-6:
        raise CalibrationError("standing calibration: neither a thigh-and-shank pair nor a shank's swing tells the "
                               "forward direction; walk a few steps after the still stand")
    return np.array([fwd[0] / n, fwd[1] / n, 0.0])


def forward_from_motion(sites: Sequence[str], quat: np.ndarray, gyro: np.ndarray | None, present: np.ndarray,
                        still: slice) -> tuple[np.ndarray, str]:
    """The forward from the knees where a thigh and a shank of one leg are worn, else from
    the shanks' swing; and which of the two it came from."""
    sites = list(sites)
    if any(t in sites and sh in sites for t, sh in KNEE_PAIRS) or gyro is None:
        return forward_from_knees(sites, quat, present, still), "knees"
    return forward_from_shanks(sites, quat, gyro, present, still), "shank swing"


def calibrate_standing(sites: Sequence[str], quat: np.ndarray, free_acc: np.ndarray | None = None,
                       acc: np.ndarray | None = None, gyro: np.ndarray | None = None,
                       present: np.ndarray | None = None, still: slice | None = None, rate: float = 60.0,
                       forward_G: np.ndarray | None = None, limits: StillnessLimits | None = None,
                       sensor_forward_G: np.ndarray | None = None) -> Calibration:
    """A ``Calibration`` from a session that starts standing still (module docstring).
    quat (T,S,4) R_GS, free_acc (T,S,3) in G or acc (T,S,3) specific force, gyro (T,S,3),
    present (T,S); ``still`` the standing frames (default ``still_start``), ``forward_G``
    the subject's forward in G (default from the knees). ``sensor_forward_G`` (S,2+):
    each sensor's own forward in its own frame (``gait_heading``), where its frame does
    not share the others' heading; NaN rows keep ``forward_G``."""
    sites = tuple(parse_sites(list(sites)))
    quat = np.asarray(quat, dtype=np.float64)
    present = np.all(np.isfinite(quat), axis=-1) if present is None else np.asarray(present, bool)
    if still is None:
        if gyro is None:
            raise CalibrationError("standing calibration: without gyro data the still start must be given")
        still = still_start(gyro, present, rate)
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
                             "still_frames": still.stop})


__all__ = ["calibrate_standing", "forward_from_knees", "forward_from_shanks", "forward_from_motion", "still_start",
           "KNEE_PAIRS"]
