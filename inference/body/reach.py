"""Hands onto tracked controllers: a two-bone reach of each arm after the model's answer.

Why: a model reads a controller's position as one input among many and places the hand
where its training says a hand with that history tends to be, centimetres from where
the controller says it is to within millimetres (the figures and the command that measures
them: docs/evaluation.md, "The three-point task"). What VR avatars do (an
arm IK after the body solve) is what this does: the upper arm and forearm are turned so
that the wrist sits where the controller's grip puts it, and the elbow goes into the plane
of the shoulder, the wrist and the elbow the model's forearm implies when hung from the
wrist (the arm's swivel is the model's forearm's, which is a measurement wherever the
controller stands for the wrist sensor; keeping the model's own elbow instead left the
forearms further off and cost GA: docs/evaluation.md); where the arm cannot reach, the
collar bone turns (up to ``COLLAR_MAX_DEG``) to bring the shoulder nearer, as a reaching
shoulder does. Every other segment is the model's answer unchanged.

Frames: the answer's own. The body is placed so that its headset point sits on the
tracked headset (the three-point papers place the body so too; ``inference.metrics.vr``),
then each tracked controller gives its hand's wrist target: the grip's position minus the
grip's offset in the hand (``inference.body.tracked.point_locals``) turned by the hand's
orientation. The positions are the model's position input (``point_features``: each point
relative to the headset's floor projection), so whatever feeds a position-input model
feeds this too.
"""

from __future__ import annotations

import numpy as np

from inference.body.body import Body, forward_kinematics
from inference.body.rotations import axis_angle_to_matrix, quat_between_vectors, quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from inference.body.tracked import TRACKED_POINTS, point_locals, point_positions

_ARMS = {side: tuple(SEGMENT_INDEX[f"{side}_{s}"] for s in ("collar", "upperarm", "forearm", "hand"))
         for side in ("l", "r")}
_EPS = 1e-4  # m: keep the elbow's triangle from folding flat
# how far a collar bone turns to bring the shoulder towards a controller the arm cannot
# reach: the clavicle's elevation and protraction each span 30-45 deg (Kapandji, The
# Physiology of the Joints, vol. 1); the lower bound keeps the shoulder a shoulder
COLLAR_MAX_DEG = 30.0
_REACH_SHARE = 0.999  # of the arm's length: beyond it the shoulder moves until the wrist is this far


def _turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T, 3, 3) the smallest turns taking directions ``a`` onto ``b`` (T, 3)."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return quat_to_matrix(quat_between_vectors(a, b))


def two_bone(shoulder: np.ndarray, elbow: np.ndarray, wrist: np.ndarray, target: np.ndarray,
             upper: float, fore: float) -> tuple[np.ndarray, np.ndarray]:
    """New (elbow, wrist) positions (T, 3) for an arm of bone lengths ``upper`` and ``fore``
    whose wrist goes to ``target`` (or as near as the arm reaches), its elbow in the plane
    of the shoulder, the target and the old elbow."""
    to_t = target - shoulder
    dist = np.linalg.norm(to_t, axis=-1, keepdims=True)
    u = to_t / np.maximum(dist, 1e-9)
    d = np.clip(dist, abs(upper - fore) + _EPS, upper + fore - _EPS)
    pole = (elbow - shoulder) - np.sum((elbow - shoulder) * u, axis=-1, keepdims=True) * u
    plen = np.linalg.norm(pole, axis=-1, keepdims=True)
    # a straight arm has no plane: bend it downwards (gravity's side), as a relaxed arm does
    down = np.array([0.0, 0.0, -1.0]) - u[..., 2:3] * u
    v = np.where(plen > 1e-6, pole / np.maximum(plen, 1e-9),
                 down / np.maximum(np.linalg.norm(down, axis=-1, keepdims=True), 1e-9))
    cos_a = np.clip((upper**2 + d**2 - fore**2) / (2 * upper * d), -1.0, 1.0)
    new_elbow = shoulder + upper * (cos_a * u + np.sqrt(1.0 - cos_a**2) * v)
    return new_elbow, shoulder + d * u


def _collar_turn(collar: np.ndarray, shoulder: np.ndarray, target: np.ndarray, reach: float,
                 max_deg: float = COLLAR_MAX_DEG) -> np.ndarray:
    """(T, 3, 3) turns of a collar bone about its joint that bring the shoulder close
    enough to ``target`` for an arm of length ``reach`` (identity where it already is),
    at most ``max_deg``."""
    L = np.linalg.norm(shoulder - collar, axis=-1)
    to_t = target - collar
    D = np.linalg.norm(to_t, axis=-1)
    now = np.arccos(np.clip(np.sum((shoulder - collar) * to_t, axis=-1) / np.maximum(L * D, 1e-12), -1, 1))
    r = _REACH_SHARE * reach
    # the angle between collar bone and target at which the shoulder is r from the target
    need = np.arccos(np.clip((D**2 + L**2 - r**2) / np.maximum(2 * D * L, 1e-12), -1.0, 1.0))
    far = np.linalg.norm(target - shoulder, axis=-1) > r
    angle = np.where(far, np.clip(now - need, 0.0, np.radians(max_deg)), 0.0)
    axis = np.cross(shoulder - collar, to_t)
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    axis = np.where(n > 1e-9, axis / np.maximum(n, 1e-12), 0.0)
    return axis_angle_to_matrix(axis * angle[:, None])


def reach_hands(R: np.ndarray, root: np.ndarray, body: Body, hands: dict[str, np.ndarray],
                features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The answer (global orientations R (T, 24, 3, 3), root (T, 3)) with each tracked
    hand's arm reaching its controller: (R, joints) after the reach.

    ``features``: the position input (T, 16) of the tracked points (the headset must be
    among them); ``hands``: segment name (``l_hand``/``r_hand``) -> its orientation (T, 3, 3)
    as the controller gives it, which the answer takes; a tracked hand not in ``hands``
    keeps the model's orientation."""
    R = np.array(R, np.float64, copy=True)
    f = np.asarray(features, np.float64)
    flags = f[:, 3 * len(TRACKED_POINTS):] > 0.5
    if not flags[:, 0].any():
        raise ValueError("reaching for the controllers needs the headset: the positions are read against it")
    for name, Rh in hands.items():
        R[:, SEGMENT_INDEX[name]] = Rh
    joints = forward_kinematics(R, root, body.offsets)
    locals_ = point_locals(body.offsets, body.height)
    head = point_positions(R, joints, locals_)[:, 0]
    # the tracked points in the answer's frame: the headset's floor projection is the origin
    # of the input, the answer's headset the anchor
    shift = head.copy()
    shift[:, 2] -= f[:, 2]
    for k, side in ((1, "l"), (2, "r")):
        on = flags[:, k] & flags[:, 0]
        if not on.any():
            continue
        co, ua, fa, ha = _ARMS[side]
        grip = f[:, 3 * k: 3 * k + 3] + shift
        target = grip - (R[:, ha] @ locals_[k][:, None])[..., 0]
        upper = float(np.linalg.norm(body.offsets[fa]))
        fore = float(np.linalg.norm(body.offsets[ha]))
        turn = _collar_turn(joints[:, co], joints[:, ua], target, upper + fore)
        R[on, co] = (turn @ R[:, co])[on]
        joints = forward_kinematics(R, root, body.offsets)
        s, e, w = joints[:, ua], joints[:, fa], joints[:, ha]
        # the elbow the model's forearm implies, hung from the target: the swivel's plane
        pole = target - (R[:, fa] @ body.offsets[ha][:, None])[..., 0]
        e2, w2 = two_bone(s, pole, w, target, upper, fore)
        R_ua = _turn(e - s, e2 - s) @ R[:, ua]
        R_fa = _turn(w - e, w2 - e2) @ R[:, fa]
        R[on, ua] = R_ua[on]
        R[on, fa] = R_fa[on]
        joints = forward_kinematics(R, root, body.offsets)
    return R, joints


__all__ = ["two_bone", "reach_hands"]
