"""Ground truth that no body makes.

Marker-based solvers sometimes fail in a way no body can move: in HDM05 the source AMC of
actor bd's four kickLFront clips holds the right foot turned ~180 deg from the shank in
every frame, and deep squats of bk and dg pass 90 deg at the ankle where a real one stops
near 40 (docs/motion_data.md). Training on such frames teaches a backwards foot, and
scoring against them charges a model for the solver's failure, so the training split can
leave such clips out, or repair them (``repair_feet``), and the evaluation can say how much
of its error sits in them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from inference.body.motion import Motion
from inference.body.rotations import (
    matrix_about_axis,
    matrix_angle_between,
    matrix_to_quat,
    quat_slerp,
    quat_to_matrix,
    rot6d_to_matrix,
)
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.features.layout import SL_ROT

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


# a foot twisted half a turn about its own bone keeps every joint where it was, so a
# marker solver can land there; it is taken for that failure only if the untwisted foot
# is a pose a body makes, with room to spare, in nearly all of a broken stretch
TWIST_ANKLE_MAX_DEG = 60.0
TWIST_SHARE = 0.9
# frames next to a broken stretch are where the solver was losing the foot
REPAIR_MARGIN_S = 0.1


@dataclass(frozen=True)
class FootRepair:
    """What ``repair_feet`` did to one clip, in frames of the clip."""

    twisted: int = 0  # turned back half a turn about the foot's bone
    interpolated: int = 0  # the ankle interpolated between the plausible frames around them
    left_broken: int = 0  # no plausible frame in the clip to interpolate from

    @property
    def changed(self) -> int:
        return self.twisted + self.interpolated


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each stretch of True."""
    d = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def repair_feet(motion: Motion, ankle_limit_deg: float = ANKLE_LIMIT_DEG,
                margin_s: float = REPAIR_MARGIN_S) -> tuple[Motion, FootRepair]:
    """The clip with each foot past ``ankle_limit_deg`` against its shank put back.

    Two failures are told apart (docs/motion_data.md). A foot turned half a turn about
    its own bone (bd's kicks: every frame, and 13-49 deg once turned back) is turned back:
    joint positions do not change, only which way the sole faces. Any other broken
    stretch (deep squats, lying down: the solver loses the foot for a fraction of a
    second) gets the ankle's rotation interpolated (slerp) between the plausible frames on
    either side, ``margin_s`` wider on each side, or held at the one side a clip edge
    leaves. The toes keep their rotation relative to the foot. Orientations change, so
    positions, sites and contacts follow when features are synthesized from the result."""
    rot = np.array(motion.rot, dtype=np.float64, copy=True)
    twisted = interpolated = left = 0
    margin = int(round(margin_s * motion.fps))
    for side in ("l", "r"):
        sh, ft, to = (SEGMENT_INDEX[f"{side}_{seg}"] for seg in ("shank", "foot", "toes"))
        ankle = np.swapaxes(rot[:, sh], -1, -2) @ rot[:, ft]
        limit = np.radians(ankle_limit_deg)
        bad = matrix_angle_between(np.eye(3), ankle) > limit
        if not bad.any():
            continue
        toes = np.swapaxes(rot[:, ft], -1, -2) @ rot[:, to]
        bone = np.asarray(motion.body.offsets[to], dtype=np.float64)
        half_turn = matrix_about_axis(bone / np.linalg.norm(bone), np.pi)
        changed = np.zeros(len(rot), dtype=bool)
        for a, b in _runs(bad):
            turned = ankle[a:b] @ half_turn
            if np.mean(matrix_angle_between(np.eye(3), turned) <= np.radians(TWIST_ANKLE_MAX_DEG)) >= TWIST_SHARE:
                ankle[a:b] = turned
                changed[a:b] = True
                twisted += b - a
        still = matrix_angle_between(np.eye(3), ankle) > limit
        if still.any():
            grown = np.convolve(still.astype(np.int8), np.ones(2 * margin + 1, dtype=np.int8), "same") > 0
            if grown.all():
                left += int(still.sum())
            else:
                q = matrix_to_quat(ankle)
                for a, b in _runs(grown):
                    if a > 0 and b < len(q):
                        w = (np.arange(a, b) - (a - 1)) / (b - (a - 1))
                        q[a:b] = quat_slerp(q[a - 1], q[b], w)
                    else:
                        q[a:b] = q[a - 1] if a > 0 else q[b]
                    ankle[a:b] = quat_to_matrix(q[a:b])
                    changed[a:b] = True
                    interpolated += b - a
        rot[changed, ft] = rot[changed, sh] @ ankle[changed]
        rot[changed, to] = rot[changed, ft] @ toes[changed]
    return replace(motion, rot=rot), FootRepair(twisted, interpolated, left)


__all__ = ["ANKLE_LIMIT_DEG", "FootRepair", "ankle_angles", "implausible_frames", "implausible_feature_frames",
           "repair_feet"]
