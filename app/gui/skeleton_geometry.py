"""The lines a skeleton is drawn with and the camera presets, without any GL: the 2D
fallback view needs them on machines where OpenGL cannot even be imported."""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import PARENTS, SEGMENT_INDEX

BONES = np.array([(i, PARENTS[i]) for i in range(1, len(PARENTS))], dtype=int)
BONE_SEGMENT = np.array([PARENTS[i] for i in range(1, len(PARENTS))], dtype=int)  # the segment a line draws
HEAD = SEGMENT_INDEX["head"]
HEAD_LENGTH_M = 0.2  # the head has no child joint: a line this long, up the head's own axis
TRAIL_POINTS = 1200
# camera presets: (elevation, azimuth) in degrees; the subject faces +X after calibration
VIEWS = {"front": (5.0, 0.0), "side": (5.0, 90.0), "top": (89.0, 0.0), "free": (10.0, -70.0),
         # in front and to the subject's left: two skeletons side by side along +Y read left to right
         "pair": (12.0, 35.0)}


def bone_segments(joints: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(2B, 3) line end points and the (B,) segment each line belongs to, head included."""
    j = np.asarray(joints, dtype=np.float64)
    n = len(BONES) + 1
    seg = np.empty((2 * n, 3))
    seg[0:-2:2] = j[BONES[:, 0]]
    seg[1:-2:2] = j[BONES[:, 1]]
    seg[-2] = j[HEAD]
    seg[-1] = j[HEAD] + np.asarray(rot, np.float64)[HEAD] @ np.array([0.0, 0.0, HEAD_LENGTH_M])
    return seg, np.append(BONE_SEGMENT, HEAD)
