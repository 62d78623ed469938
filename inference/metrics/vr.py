"""The metrics of the three-point (headset + two controllers) papers, on our skeleton.

AGRoL (Du et al., CVPR 2023, Sec. 4.2) and HAD (Niu et al., Sec. 4.2, which cites AGRoL
for the position metrics, AvatarPoser for MPJVE and PIP for jitter) report MPJRE (deg),
MPJPE, Hand/Upper/Lower/Root PE (cm), MPJVE (cm/s) and Jitter (10^2 m/s^3). The papers'
text only names them; the definitions below are those of AGRoL's evaluation code
(facebookresearch/AGRoL, ``test.py`` and ``utils/metrics.py``), read and rewritten here:

- Joints: SMPL's first 22 joints (pelvis ... wrists); SMPL's two hand joints (our
  ``l_fingers``/``r_fingers`` joints 22, 23) are left out. Our joint ``i`` is where
  segment ``i`` starts and the tree is SMPL's, so joint ``i`` here is SMPL joint ``i``.
- Frame: global, but the predicted body is translated, frame by frame, so that its head
  joint (15) sits on the true head joint: AGRoL's model predicts no translation and
  places the body under the tracked headset, whose position is the true head joint's.
  ``anchor="head"`` does that (the papers' protocol, and what ``evaluate_clip`` uses);
  ``anchor=None`` scores the positions as given, root drift included.
- Upper body: joints 3, 6, 9, 12-21 (spine1-3, neck, collars, head, shoulders, elbows,
  wrists = our spine1, spine2, spine3, neck, l/r_collar, head, l/r_upperarm,
  l/r_forearm, l/r_hand joints). Lower body: 0, 1, 2, 4, 5, 7, 8, 10, 11 (pelvis, hips,
  knees, ankles, toe bases = our pelvis, l/r_thigh, l/r_shank, l/r_foot, l/r_toes
  joints): the pelvis counts as lower body. Hands: 20, 21 (the wrists = our l_hand,
  r_hand joints). Root: 0 (pelvis).
- MPJRE is *not* a geodesic angle: the mean absolute difference of the axis-angle
  *components* of the 21 local (parent-relative) joint rotations 1..21, each component
  difference wrapped into [-pi, pi]; the root's global orientation is left out. A 30 deg
  turn of one joint about a frame axis therefore counts 30/63 deg. Our local rotations
  are relative to the T-pose with world-aligned axes, as SMPL's are, and our frame is
  SMPL's up to a signed permutation of the axes (Z up instead of Y up), which leaves the
  sum of absolute components unchanged. ``la_deg`` (errors.py) is the geodesic reading.
- MPJVE: mean over joints and frame pairs of || (p[t+1]-p[t]) - (q[t+1]-q[t]) || * fps.
- Jitter: mean over joints and frames of the predicted joints' jerk magnitude, the third
  finite difference times fps^3, in the head-anchored frame; the papers print it in
  10^2 m/s^3 (AGRoL's code gives m/s^3, its tables divide by 100: truth 4.00 = 400 m/s^3
  on AMASS at 60 fps). imucap's ``jitter_ratio`` (prediction over truth, all 24 joints,
  unanchored) stays beside it.

Where ours differs: the papers evaluate at 60 fps and average each clip's means over
clips; ``errors.summarize`` evaluates at the model's 20 Hz and pools frames over clips.
The frame rate changes MPJVE and jitter (finite differences over 50 ms instead of
16.7 ms smooth away frame-to-frame noise), so those two are not comparable with the
papers' figures across rates, only between models scored here. Every function returns
SI units (m, m/s, m/s^3, deg) per frame or per sample; ``summarize`` scales to the
papers' units.
"""

from __future__ import annotations

import numpy as np

from inference.body.body import local_from_global
from inference.body.rotations import matrix_to_axis_angle

BODY_JOINTS: tuple[int, ...] = tuple(range(22))
ROOT_JOINT = 0
HEAD_JOINT = 15
HAND_JOINTS: tuple[int, ...] = (20, 21)
UPPER_JOINTS: tuple[int, ...] = (3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21)
LOWER_JOINTS: tuple[int, ...] = (0, 1, 2, 4, 5, 7, 8, 10, 11)
ROTATION_JOINTS: tuple[int, ...] = tuple(range(1, 22))  # SMPL's pose_body: root excluded
ANCHORS = ("head", None)


def _check_anchor(anchor: str | None) -> None:
    if anchor not in ANCHORS:
        raise ValueError(f"anchor must be 'head' or None, not {anchor!r}")


def head_anchored(j_pred: np.ndarray, j_true: np.ndarray) -> np.ndarray:
    """The predicted joints (T, J, 3) translated per frame so that the predicted head joint
    is on the true one: the papers put the body under the tracked headset (module
    docstring), so a model's own translation (and its drift) does not count."""
    jp = np.asarray(j_pred, np.float64)
    jt = np.asarray(j_true, np.float64)
    return jp + (jt[:, HEAD_JOINT] - jp[:, HEAD_JOINT])[:, None, :]


def _positions(j_pred: np.ndarray, j_true: np.ndarray, anchor: str | None) -> tuple[np.ndarray, np.ndarray]:
    _check_anchor(anchor)
    jp = np.asarray(j_pred, np.float64)
    jt = np.asarray(j_true, np.float64)
    if jp.shape != jt.shape or jp.ndim != 3 or jp.shape[1] < len(BODY_JOINTS) or jp.shape[2] != 3:
        raise ValueError(f"joint positions must be (T, 24, 3) alike; got {jp.shape} and {jt.shape}")
    if anchor == "head":
        jp = head_anchored(jp, jt)
    return jp[:, list(BODY_JOINTS)], jt[:, list(BODY_JOINTS)]


def joint_distances(j_pred: np.ndarray, j_true: np.ndarray, anchor: str | None = "head") -> np.ndarray:
    """(T, 22) distance (m) of each of SMPL's 22 body joints, after ``anchor``."""
    jp, jt = _positions(j_pred, j_true, anchor)
    return np.linalg.norm(jp - jt, axis=-1)


def mpjpe(j_pred: np.ndarray, j_true: np.ndarray, anchor: str | None = "head") -> np.ndarray:
    """(T,) MPJPE per frame (m): mean distance over the 22 body joints."""
    return joint_distances(j_pred, j_true, anchor).mean(axis=1)


def part_pe(j_pred: np.ndarray, j_true: np.ndarray, joints: tuple[int, ...],
            anchor: str | None = "head") -> np.ndarray:
    """(T,) mean distance (m) over a joint set (HAND_JOINTS, UPPER_JOINTS, LOWER_JOINTS,
    (ROOT_JOINT,)): Hand, Upper, Lower and Root PE per frame."""
    return joint_distances(j_pred, j_true, anchor)[:, list(joints)].mean(axis=1)


def mpjve(j_pred: np.ndarray, j_true: np.ndarray, fps: float, anchor: str | None = "head") -> np.ndarray:
    """(T-1,) MPJVE per frame pair (m/s): mean over the 22 joints of the norm of the
    velocity difference, velocities by forward differences times fps; empty for T < 2."""
    jp, jt = _positions(j_pred, j_true, anchor)
    if jp.shape[0] < 2:
        return np.zeros(0)
    dv = (jp[1:] - jp[:-1]) - (jt[1:] - jt[:-1])
    return np.linalg.norm(dv, axis=-1).mean(axis=1) * fps


def mean_jerk(joints: np.ndarray, fps: float) -> np.ndarray:
    """(T-3,) the papers' jitter per sample (m/s^3): mean over the 22 body joints of the
    norm of the third finite difference times fps^3; empty for T < 4. Feed it the
    head-anchored prediction (``head_anchored``) to match the papers, or the truth."""
    j = np.asarray(joints, np.float64)[:, list(BODY_JOINTS)]
    if j.shape[0] < 4:
        return np.zeros(0)
    d3 = j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3]
    return np.linalg.norm(d3, axis=-1).mean(axis=1) * fps**3


def mpjre_local(L_pred: np.ndarray, L_true: np.ndarray) -> np.ndarray:
    """(T,) MPJRE per frame (deg) from local (parent-relative) rotations (T, 24, 3, 3):
    mean over joints 1..21 and the three axis-angle components of the absolute component
    difference, wrapped into [-180, 180] deg (module docstring: not a geodesic angle)."""
    ap = matrix_to_axis_angle(np.asarray(L_pred, np.float64)[:, list(ROTATION_JOINTS)])
    at = matrix_to_axis_angle(np.asarray(L_true, np.float64)[:, list(ROTATION_JOINTS)])
    d = (at - ap + np.pi) % (2 * np.pi) - np.pi
    return np.rad2deg(np.abs(d)).mean(axis=(1, 2))


def mpjre(R_pred: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """(T,) MPJRE per frame (deg) from global orientations R_WB (T, 24, 3, 3)."""
    return mpjre_local(local_from_global(np.asarray(R_pred, np.float64)),
                       local_from_global(np.asarray(R_true, np.float64)))


__all__ = [
    "BODY_JOINTS", "ROOT_JOINT", "HEAD_JOINT", "HAND_JOINTS", "UPPER_JOINTS", "LOWER_JOINTS", "ROTATION_JOINTS",
    "head_anchored", "joint_distances", "mpjpe", "part_pe", "mpjve", "mean_jerk", "mpjre_local", "mpjre",
]
