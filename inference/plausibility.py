"""Ground truth that no body makes.

Marker-based solvers sometimes fail in a way no body can move: in HDM05 the source AMC of
actor bd's four kickLFront clips holds the right foot turned ~180 deg from the shank in
every frame, and deep squats of bk and dg pass 90 deg at the ankle where a real one stops
near 40 (NOTES.md, session 12). Training on such frames teaches a backwards foot, and
scoring against them charges a model for the solver's failure, so the training split can
leave such clips out and the evaluation can say how much of its error sits in them.
"""

from __future__ import annotations

import numpy as np

from .features import SL_ROT
from .rotations import matrix_angle_between, rot6d_to_matrix
from .skeleton import N_SEGMENTS, SEGMENT_INDEX

# a deep squat bends the ankle ~40 deg from the standing pose; a foot rotated past 90 deg
# against its shank is a fitting failure
ANKLE_LIMIT_DEG = 90.0
_ANKLES = tuple((SEGMENT_INDEX[f"{s}_shank"], SEGMENT_INDEX[f"{s}_foot"]) for s in ("l", "r"))


def ankle_angles(rot: np.ndarray) -> np.ndarray:
    """(T, 2) degrees: each foot's rotation from its standing pose relative to its shank
    (left, right), from global segment orientations (T, 24, 3, 3)."""
    rot = np.asarray(rot, dtype=np.float64)
    return np.degrees(np.stack([matrix_angle_between(rot[:, s], rot[:, f]) for s, f in _ANKLES], axis=-1))


def implausible_frames(rot: np.ndarray, ankle_limit_deg: float = ANKLE_LIMIT_DEG) -> np.ndarray:
    """(T,) bool: frames whose pose no body makes (an ankle past ``ankle_limit_deg``)."""
    return (ankle_angles(rot) > ankle_limit_deg).any(axis=-1)


def implausible_feature_frames(features: np.ndarray, ankle_limit_deg: float = ANKLE_LIMIT_DEG) -> np.ndarray:
    """``implausible_frames`` of a clip's feature rows (T, 190)."""
    f = np.asarray(features, dtype=np.float64)
    rot = rot6d_to_matrix(f[:, SL_ROT].reshape(len(f), N_SEGMENTS, 6))
    return implausible_frames(rot, ankle_limit_deg)


__all__ = ["ANKLE_LIMIT_DEG", "ankle_angles", "implausible_frames", "implausible_feature_frames"]
