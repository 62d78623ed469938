"""What both sides of a comparison can give, whatever they measured: joint centres, the
directions of the segments between them, and joint flexion angles from those directions.

Why directions and not orientations for everything: a marker reference (C3D, TRC) knows
where joint centres are, not how a bone is twisted about its own axis. Computing the
joint angles of both sides from joint centres, the same way, keeps a definition that
differs between the two systems out of the error (a knee angle from orientations would
carry the twist, one from markers would not).

Joint angles (deg), from joint centres in a Z-up world:
- knee, elbow: the angle between the proximal and distal segment (0 = straight);
- hip: the thigh's angle from the vertical in the pelvis's sagittal plane (the plane
  normal to the line between the hip centres), forward positive. Joint centres do not
  carry the pelvis's tilt, so this is thigh inclination, not hip flexion relative to the
  pelvis: both sides are measured the same way.
"""

from __future__ import annotations

import numpy as np

from app.export.markers import JOINT_NAMES
from inference.body.skeleton import SEGMENT_INDEX

# joint centre (marker) names: joint i is where segment i starts (DESIGN.md); the C3D/TRC exports write them
JOINT_INDEX: dict[str, int] = {j: SEGMENT_INDEX[s] for s, j in JOINT_NAMES.items()}

# segment -> (from joint, to joint): the direction compared for a marker reference. The
# pelvis has no long axis between two joint centres; its left-right axis stands for it.
DIRECTIONS: dict[str, tuple[str, str]] = {
    "pelvis": ("r_hip", "l_hip"),
    "spine3": ("spine3", "neck"),
    **{f"{s}_{seg}": (f"{s}_{a}", f"{s}_{b}") for s in "lr" for seg, a, b in (
        ("thigh", "hip", "knee"), ("shank", "knee", "ankle"), ("foot", "ankle", "mtp"),
        ("upperarm", "shoulder", "elbow"), ("forearm", "elbow", "wrist"))},
}

# joint -> (kind, joints it needs)
JOINT_ANGLES: dict[str, tuple[str, tuple[str, ...]]] = {
    **{f"{s}_knee": ("hinge", (f"{s}_hip", f"{s}_knee", f"{s}_ankle")) for s in "lr"},
    **{f"{s}_hip": ("hip", (f"{s}_hip", f"{s}_knee", "l_hip", "r_hip")) for s in "lr"},
    **{f"{s}_elbow": ("hinge", (f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist")) for s in "lr"},
}


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-9, n, np.nan)


def directions(joints: np.ndarray, have: set[str]) -> dict[str, np.ndarray]:
    """segment -> (T, 3) unit direction, for the segments whose two joints are in ``have``."""
    out = {}
    for seg, (a, b) in DIRECTIONS.items():
        if a in have and b in have:
            out[seg] = _unit(joints[:, JOINT_INDEX[b]] - joints[:, JOINT_INDEX[a]])
    return out


def joint_angles(joints: np.ndarray, have: set[str]) -> dict[str, np.ndarray]:
    """joint -> (T,) flexion angle in degrees (module docstring), for the joints whose
    centres are in ``have``; joints (T, 24, 3) in a Z-up world, indexed as ``JOINT_INDEX``."""
    P = {j: joints[:, i] for j, i in JOINT_INDEX.items() if j in have}
    out: dict[str, np.ndarray] = {}
    for name, (kind, need) in JOINT_ANGLES.items():
        if not all(j in P for j in need):
            continue
        if kind == "hinge":
            a, b, c = (P[j] for j in need)
            u, v = _unit(b - a), _unit(c - b)
            out[name] = np.rad2deg(np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0)))
        else:
            hip, knee, lh, rh = (P[j] for j in need)
            left = _unit(lh - rh)
            up = np.array([0.0, 0.0, 1.0])
            fwd = _unit(np.cross(left, up))
            down = np.cross(left, fwd)  # in the sagittal plane, perpendicular to forward
            thigh = knee - hip
            out[name] = np.rad2deg(np.arctan2(np.sum(thigh * fwd, axis=-1), np.sum(thigh * down, axis=-1)))
    return out


__all__ = ["JOINT_NAMES", "JOINT_INDEX", "DIRECTIONS", "JOINT_ANGLES", "directions", "joint_angles"]
