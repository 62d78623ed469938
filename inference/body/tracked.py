"""Where a VR headset, two hand controllers and a waist tracker sit on the body, and the
per-frame position input a model takes from them.

Why here: the simulated rig (``sim_devices/devices/vr_rig.py``) puts its devices on a
motion, the training derives the same points from every window it draws, and an
evaluation scores models that read them: one geometry for all three, on numpy arrays and
torch tensors alike (``points_on_segments``, as forward kinematics does).

Placement (fractions of body height H, so a smaller body carries them where a smaller
person would):
- headset: between the eyes, where OpenVR puts an HMD's pose: 0.05 H ahead of and 0.07 H
  above the head joint (0.936 H standing, Drillis & Contini's eye height); the head's
  orientation;
- controllers: the grip pose's origin inside the fist, 0.6 of the way from the wrist to
  the knuckles along the hand bone and 0.02 H to the palm side; the hand's orientation
  turned by ``GRIP_PITCH_DEG`` about its lateral axis (``grip_rotation``);
- waist tracker: the pelvis sensor site (the sacrum, ``body._SITE_PLACEMENT``).

The position input (``point_features``): per frame and point, its position minus the
headset's floor projection (x, y of the headset, z 0), in world axes, and a presence
flag; absent points are zeros. Relative to the headset because a headset is what every
VR user wears and the model's window has no absolute place; world axes because the
model's orientations are world-frame too. ``POINT_FEATURES`` = 4 x (3 + 1) = 16 numbers.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from inference.body.body import _as_like, _xp, points_on_segments
from inference.body.rotations import axis_angle_to_matrix
from inference.body.skeleton import SEGMENT_INDEX

TRACKED_POINTS: tuple[str, ...] = ("head", "l_hand", "r_hand", "pelvis")
POINT_SEGMENTS: tuple[int, ...] = tuple(SEGMENT_INDEX[s] for s in TRACKED_POINTS)
POINT_FEATURES = 4 * len(TRACKED_POINTS)
THREE_POINTS: tuple[str, ...] = ("head", "l_hand", "r_hand")

HMD_OFFSET_H = (0.05, 0.0, 0.07)  # head segment frame, x body height: between the eyes
GRIP_ALONG = 0.6  # of the wrist -> knuckles bone
GRIP_PALM_H = 0.02  # x body height, to the palm side (-Z of the hand in the T-pose)
GRIP_PITCH_DEG = 30.0
PELVIS_TRACKER_H = (-0.055, 0.0, 0.02)  # the pelvis sensor site (sacrum), x body height
EYE_HEIGHT_RATIO = 0.936  # Drillis & Contini: eye height / body height; headset height -> H


def grip_rotation(pitch_deg: float = GRIP_PITCH_DEG) -> np.ndarray:
    """Controller frame in the hand segment's frame: a turn about the hand's lateral axis."""
    return axis_angle_to_matrix(np.array([0.0, math.radians(pitch_deg), 0.0]))


def point_locals(offsets: Any, height: Any) -> Any:
    """Each point's offset from its segment's joint, in the segment frame: (..., 4, 3) for
    bone offsets (..., 24, 3) and heights (...) (numpy or torch)."""
    xp = _xp(offsets)
    h = _as_like(height, offsets)[..., None]
    fingers = {s: offsets[..., SEGMENT_INDEX[s[0] + "_fingers"], :] for s in ("l_hand", "r_hand")}
    palm = _as_like([0.0, 0.0, -GRIP_PALM_H], offsets) * h
    rows = [_as_like(HMD_OFFSET_H, offsets) * h,
            GRIP_ALONG * fingers["l_hand"] + palm,
            GRIP_ALONG * fingers["r_hand"] + palm,
            _as_like(PELVIS_TRACKER_H, offsets) * h]
    return xp.stack(rows, axis=-2) if xp is np else xp.stack(rows, dim=-2)


def point_positions(R: Any, joints: Any, locals_: Any) -> Any:
    """World positions (..., 4, 3) of the four points, for global orientations R (..., 24,
    3, 3), joints (..., 24, 3) and ``point_locals`` (4, 3) or broadcastable."""
    return points_on_segments(R, joints, POINT_SEGMENTS, locals_)


def point_features(positions: Any, present: Any) -> Any:
    """The model's position input (..., 16) from positions (..., 4, 3) in world and
    presence (..., 4) or (4,) bool: each present point's position minus the headset's
    floor projection, then the four flags. Without a present headset every point reads
    absent (nothing to place them against)."""
    xp = _xp(positions)
    pres = _as_like(present, positions)
    pres = pres * 1.0 if xp is np else pres.to(positions.dtype)
    pres = pres + 0 * positions[..., 0]  # broadcast to (..., 4)
    pres = pres * pres[..., :1]  # no headset, no points
    head = positions[..., :1, :] * _as_like([1.0, 1.0, 0.0], positions)
    rel = (positions - head) * pres[..., None]
    flat = rel.reshape(*rel.shape[:-2], 12)
    return xp.concatenate([flat, pres], axis=-1) if xp is np else xp.cat([flat, pres], dim=-1)


def mirror_point_features(f: Any) -> Any:
    """``point_features`` (..., 16) of the body reflected in its sagittal plane (world y ->
    -y, left and right swapped), as ``inference.features.mirror`` reflects the features."""
    n = len(TRACKED_POINTS)
    swap = [TRACKED_POINTS.index({"l_hand": "r_hand", "r_hand": "l_hand"}.get(p, p)) for p in TRACKED_POINTS]
    idx = [3 * j + k for j in swap for k in range(3)] + [3 * n + j for j in swap]
    sign = [1.0, -1.0, 1.0] * n + [1.0] * n
    return f[..., idx] * _as_like(sign, f)


def presence(points: tuple[str, ...] | list[str]) -> np.ndarray:
    """(4,) bool flags of the named points (``TRACKED_POINTS`` order)."""
    unknown = sorted(set(points) - set(TRACKED_POINTS))
    if unknown:
        raise ValueError(f"unknown tracked point(s) {', '.join(unknown)} (known: {', '.join(TRACKED_POINTS)})")
    return np.array([p in points for p in TRACKED_POINTS])


__all__ = ["TRACKED_POINTS", "THREE_POINTS", "POINT_SEGMENTS", "POINT_FEATURES", "grip_rotation", "point_locals",
           "point_positions", "point_features", "mirror_point_features", "presence"]
