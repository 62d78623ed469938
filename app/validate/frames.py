"""Segment orientations from what a marker reference knows, so that its joint angles come
from the one definition (``inference.metrics.joint_angles``) like every other angle.

An anatomical frame is three axes in our world: anterior, proximal (along the bone,
towards the parent joint) and right, as OpenSim's body frames (X anterior, Y proximal,
Z right) and the ISB recommendations (Wu et al. 2002, 2005) define them. Such a frame A
(columns) is OpenSim's body frame in our world, so our segment orientation is
R = A M_OS Q (``joint_angles``: G_os = M_OS R Q^T M_OS^T, and G_os = M_OS A).

Where a frame comes from, best first (``markers.py`` decides which a file has):
- the segment axes a lab's software writes (Plug-in Gait's ``PELO/PELA/PELL/PELP``...:
  origin, anterior, left, proximal points);
- anatomical landmarks: the epicondyles and malleoli give the knee and ankle axes, the
  ASIS and PSIS (or sacrum) the pelvis;
- joint centres only (``hinge_frames``): the long axis between two centres, and the
  knee's or elbow's hinge axis from the plane of the three centres around it, signed
  by the body's left-right axis (pelvis for the legs, shoulders for the arms) and blended
  into it when the limb is nearly straight, where that plane is undefined. Flexion is
  then the signed angle between the two long axes (hyperextension negative), and the
  ab/adduction and rotation of the knee and elbow are zero by construction.
"""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import SEGMENT_INDEX
from inference.metrics.joint_angles import M_OS, opensim_default_pose

# below this hinge angle the plane of three joint centres gives way to the body's axis
HINGE_BLEND = np.sin(np.deg2rad(10.0))

_Q = opensim_default_pose()


def unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-9, n, np.nan)


def segment_from_axes(proximal: np.ndarray, right: np.ndarray, segment: str) -> np.ndarray:
    """(T, 3, 3) our orientation of ``segment`` from its proximal (long) axis and a right
    axis (made orthogonal to it), both (T, 3) in our world; NaN where either is."""
    y = unit(proximal)
    z = unit(right - np.sum(right * y, axis=-1, keepdims=True) * y)
    x = np.cross(y, z)
    A = np.stack([x, y, z], axis=-1)
    return A @ M_OS @ _Q[SEGMENT_INDEX[segment]]


def segment_from_anterior(anterior: np.ndarray, proximal: np.ndarray, segment: str) -> np.ndarray:
    """As ``segment_from_axes``, from an anterior and a proximal axis (proximal kept)."""
    y = unit(proximal)
    x = unit(anterior - np.sum(anterior * y, axis=-1, keepdims=True) * y)
    return segment_from_axes(y, np.cross(x, y), segment)


def hinge_axis(a: np.ndarray, b: np.ndarray, c: np.ndarray, body_right: np.ndarray) -> np.ndarray:
    """(T, 3) unit right-pointing hinge axis at b between segments a->b and b->c: the normal
    of their plane, signed to agree with ``body_right``, blended into it as the angle
    between the segments goes to zero."""
    u = unit(b - a)
    n = np.cross(u, unit(c - b))  # |n| = sin(angle between the segments)
    r = unit(body_right)
    # a limb along the body's left-right axis (arms in a T-pose): that axis says nothing
    # about the hinge; a horizontal one across the limb stands in for it (flexion ~0 there)
    across = r - np.sum(r * u, axis=-1, keepdims=True) * u
    side = np.cross(u, [0.0, 0.0, 1.0])
    side = np.where(np.sum(side * r, axis=-1, keepdims=True) < 0, -side, side)
    r = np.where(np.linalg.norm(across, axis=-1, keepdims=True) < 0.2, unit(side), r)
    sign = np.where(np.sum(n * r, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return unit(sign * n + HINGE_BLEND * r)


def hinge_frames(P: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """segment -> (T, 3, 3) orientations from joint centres ``P`` (name -> (T, 3), our
    world, the names of ``app.export.markers``): the pelvis, thighs, shanks, upper arms
    and forearms whose centres are there (module docstring)."""
    out: dict[str, np.ndarray] = {}
    up = np.array([0.0, 0.0, 1.0])
    pelvis_right = P["r_hip"] - P["l_hip"] if "l_hip" in P and "r_hip" in P else None
    if pelvis_right is not None:
        trunk = (P["spine1"] - P["pelvis"]) if "spine1" in P and "pelvis" in P else np.broadcast_to(
            up, pelvis_right.shape)
        out["pelvis"] = segment_from_axes(np.cross(pelvis_right, np.cross(trunk, pelvis_right)), pelvis_right,
                                          "pelvis")
    arm_right = P["r_shoulder"] - P["l_shoulder"] if "l_shoulder" in P and "r_shoulder" in P else None
    for s in "lr":
        for right, (top, mid, end), (upper, lower) in (
                (pelvis_right, ("hip", "knee", "ankle"), ("thigh", "shank")),
                (arm_right, ("shoulder", "elbow", "wrist"), ("upperarm", "forearm"))):
            a, b, c = (P.get(f"{s}_{j}") for j in (top, mid, end))
            if right is None or a is None or b is None or c is None:
                continue
            axis = hinge_axis(a, b, c, right)
            out[f"{s}_{upper}"] = segment_from_axes(a - b, axis, f"{s}_{upper}")
            out[f"{s}_{lower}"] = segment_from_axes(b - c, axis, f"{s}_{lower}")
    return out


__all__ = ["segment_from_axes", "segment_from_anterior", "hinge_axis", "hinge_frames", "unit", "HINGE_BLEND"]
