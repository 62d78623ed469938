"""The heading toolkit: where "forward" is, from how the legs move, and how far the subject has turned.

Why one module: the standing calibration (``standing``), the walk protocol (``walk``), the
gait headings of an import (``gait_heading``) and the calibration from another trial
(``trials``) all answer the same two questions, and each answer must mean the same thing
in all of them:

- **how far has the subject turned** since a reference moment (``heading_change``), so that
  a vector seen after a turn can be turned back into the reference heading (``turn_back``):
  a walk back after a turn then votes for the same forward as the walk out;
- **which way is forward**, from the legs: the swing axis of a thigh or shank (the principal
  axis of its horizontal angular velocity is lateral; ``swing_axis`` and the two ways of
  signing it, by its fastest tenth or by its third moment), and the knees' flexion
  (``forward_from_knees``: a knee bends only one way).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from inference.body.conventions import turn_xy, yaw_of
from inference.body.rotations import quat_to_matrix

from .core import CalibrationError, mean_rotation

KNEE_PAIRS = (("l_thigh", "l_shank"), ("r_thigh", "r_shank"))
DOWN = np.array([0.0, 0.0, -1.0])
MIN_BEND_DEG = 20.0  # a knee must bend this far at least once for its plane to count
MIN_SWING_DEG_S = 30.0  # a shank turning slower than this is standing, not swinging
MIN_SWING_SKEW = 0.3  # below it the swing peaks do not stand out: forward and backward look alike


def still_mean(R: np.ndarray, ok: np.ndarray, still: slice) -> np.ndarray:
    """(3,3) one sensor's mean orientation over a still window (R (T,3,3), ok (T,))."""
    return mean_rotation(np.where(ok[still][:, None, None], R[still], np.nan)[:, None])[0]


def heading_change(R: np.ndarray, ok: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(T,) how far (rad) one sensor has turned about the vertical since it was ``ref``
    (3,3); NaN where it did not deliver. Independent of the sensor's own heading offset,
    which cancels in R ref^T."""
    return np.where(ok, yaw_of(R @ ref.T), np.nan)


def turn_back(v: np.ndarray, angle: np.ndarray | None) -> np.ndarray:
    """(N,2) horizontal vectors turned by -angle (rad): into the heading the subject had at
    the reference moment. ``angle`` None: unchanged (a straight walk)."""
    return v if angle is None else turn_xy(v, -np.asarray(angle))


def principal_axis(w: np.ndarray) -> np.ndarray:
    """Unit (D,) main axis of vectors w (N,D), sign arbitrary: a hinge's rotation axis from
    its angular velocities."""
    return np.linalg.eigh(w.T @ w)[1][:, -1]


def right_to_forward(right: np.ndarray) -> np.ndarray:
    """Forward (...,2) = z x right, for a horizontal axis pointing to the subject's right."""
    return np.stack([-right[..., 1], right[..., 0]], axis=-1)


def forward_to_right(f: np.ndarray) -> np.ndarray:
    """The right (2,) of a forward: forward turned by -90 deg (the inverse of z x right)."""
    return np.array([f[1], -f[0]])


def peak_forward(w: np.ndarray) -> np.ndarray:
    """Forward (2,) from horizontal angular velocities (N,2): the mean of the fastest tenth
    points right (a leg segment turns fastest when its lower end goes forward)."""
    mag = np.linalg.norm(w, axis=-1)
    return right_to_forward(w[mag >= np.quantile(mag, 0.9)].mean(0))


def axis_forward(w: np.ndarray, sign_from: np.ndarray | None = None) -> np.ndarray:
    """Forward (2,) from the swing axis of horizontal angular velocities (N,2), signed by the
    fastest tenth's mean (of ``sign_from`` when given): a stretch of a log whose peaks read
    backwards (a slower walk back) still gives the axis."""
    axis = principal_axis(w)
    if float(axis @ forward_to_right(peak_forward(w if sign_from is None else sign_from))) < 0:
        axis = -axis
    return right_to_forward(axis)


def skew_forward(w: np.ndarray) -> tuple[np.ndarray, float]:
    """Forward (2,) from the swing axis of horizontal angular velocities (N,2), signed so that
    the swing peaks are the large ones (positive third moment), and that skew: for a shank,
    whose forward swing is much faster than its backward one."""
    a = principal_axis(w)
    p = w @ a
    skew = float(np.mean(p**3) / np.mean(p**2) ** 1.5)
    return right_to_forward(a if skew > 0 else -a), skew


def _pose_matrices(quat: np.ndarray, ok: np.ndarray) -> np.ndarray:
    return quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))


def forward_from_knees(sites: Sequence[str], quat: np.ndarray, present: np.ndarray, still: slice) -> np.ndarray:
    """(3,) the subject's forward in the sensors' shared frame G, horizontal, unit, from the
    knees' flexion over the whole session: with each bone's down axis fixed from the stand,
    the horizontal part of (shank-down - thigh-down) points backward whenever a knee bends.
    quat (T,S,4) R_GS.

    The subject turns during a session, and a walk back bends the knees the other way in G:
    each frame's vote is turned back by how far the pelvis (else that leg's thigh) has turned
    since the stand, so every frame votes for the forward *at calibration*."""
    sites = list(sites)
    quat = np.asarray(quat, dtype=np.float64)
    ok = np.all(np.isfinite(quat), axis=-1) & np.asarray(present, bool)
    R = _pose_matrices(quat, ok)

    def turn_of(k: int) -> np.ndarray:
        return heading_change(R[:, k], ok[:, k], still_mean(R[:, k], ok[:, k], still))

    pelvis = sites.index("pelvis") if "pelvis" in sites and ok[still, sites.index("pelvis")].any() else None
    pelvis_turn = turn_of(pelvis) if pelvis is not None else None
    back = np.zeros(3)
    pairs = seen = 0
    for thigh, shank in KNEE_PAIRS:
        if thigh not in sites or shank not in sites:
            continue
        i, j = sites.index(thigh), sites.index(shank)
        both = ok[:, i] & ok[:, j]
        if not both[still].any() or both.sum() < 2:
            continue
        d_thigh = R[both, i] @ (still_mean(R[:, i], ok[:, i], still).T @ DOWN)
        d_shank = R[both, j] @ (still_mean(R[:, j], ok[:, j], still).T @ DOWN)
        bend = d_shank - d_thigh
        turned = (pelvis_turn if pelvis_turn is not None else turn_of(i))[both]
        angle = np.degrees(2.0 * np.arcsin(np.clip(np.linalg.norm(bend, axis=1) / 2.0, 0.0, 1.0)))
        bent = (angle > MIN_BEND_DEG / 2) & np.isfinite(turned)  # a straight knee's bend is noise in any direction
        if angle.max(initial=0.0) >= MIN_BEND_DEG:
            back[:2] += turn_back(bend[bent, :2], turned[bent]).sum(axis=0)
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
    thigh (the paper's six: pelvis, head, wrists, shanks): each shank's world-frame angular
    velocity, turned back by the pelvis's turn since the stand, over the frames it swings,
    gives a forward by ``skew_forward``; refused below |skew| MIN_SWING_SKEW. gyro (T,S,3)
    rad/s in the sensor frame."""
    sites = list(sites)
    quat = np.asarray(quat, dtype=np.float64)
    gyro = np.asarray(gyro, dtype=np.float64)
    ok = np.all(np.isfinite(quat), axis=-1) & np.asarray(present, bool) & np.all(np.isfinite(gyro), axis=-1)
    R = _pose_matrices(quat, ok)
    p = sites.index("pelvis") if "pelvis" in sites else None
    turned = (heading_change(R[:, p], ok[:, p], still_mean(R[:, p], ok[:, p], still)) if p is not None
              else np.zeros(len(quat)))
    fwd = np.zeros(2)
    used = []
    for s in ("l_shank", "r_shank"):
        if s not in sites:
            continue
        k = sites.index(s)
        use = ok[:, k] & np.isfinite(turned)
        w = turn_back(np.einsum("tij,tj->ti", R[use, k], gyro[use, k])[:, :2], turned[use])
        w = w[np.linalg.norm(w, axis=1) > np.deg2rad(MIN_SWING_DEG_S)]
        if len(w) < 10:
            continue
        f, skew = skew_forward(w)
        if abs(skew) < MIN_SWING_SKEW:
            continue
        fwd += f
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


__all__ = ["DOWN", "KNEE_PAIRS", "axis_forward", "forward_from_knees", "forward_from_motion", "forward_from_shanks",
           "forward_to_right", "heading_change", "peak_forward", "principal_axis", "right_to_forward",
           "skew_forward", "still_mean", "turn_back"]
