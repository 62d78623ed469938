"""One frame's forward kinematics on small numpy arrays: the live poser's per-frame path
(``inference/poser/poser.py``, ``Poser.finish``).

Why beside ``body``: its FK broadcasts and converts for any batch, which on one frame's 24
segments is most of the cost; here the ancestry and index arrays are prepared once. The
rotation side of the same path (6D, quaternions, logs, turns about an axis) is the
``*_np`` section of ``inference.body.rotations``, next to the general formulas it mirrors.
tests/inference/body/test_frame_kernels.py checks both against their general counterparts.

Keeps its input's float dtype (float32 in, float32 out, as the poser's torch path computed it).
"""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import N_SEGMENTS, PARENTS

# forward kinematics: joint i is the sum of its ancestors' rotated offsets (global orientations)
_PAR = np.array([max(p, 0) for p in PARENTS])


def _ancestry() -> np.ndarray:
    A = np.zeros((N_SEGMENTS, N_SEGMENTS))
    for i in range(1, N_SEGMENTS):
        j = i
        while j > 0:
            A[i, j] = 1.0
            j = PARENTS[j]
    return A


_ANCESTRY = _ancestry()


class Kinematics:
    """Forward kinematics of one body for single frames: ``body.forward_kinematics`` with
    the offsets and index arrays prepared once."""

    def __init__(self, offsets: np.ndarray, dtype=np.float32) -> None:
        self.offsets = np.asarray(offsets, dtype=dtype).reshape(N_SEGMENTS, 3, 1)
        self.ancestry = _ANCESTRY.astype(dtype)

    def joints(self, R: np.ndarray) -> np.ndarray:
        """(24, 3, 3) global orientations -> (24, 3) joints with the root at the origin."""
        return self.ancestry @ (R.take(_PAR, 0) @ self.offsets)[..., 0]


def points_on_segments(R: np.ndarray, joints: np.ndarray, segments: np.ndarray, local: np.ndarray) -> np.ndarray:
    """(K, 3) world positions of K points (``local`` (K, 3, 1)) on ``segments``: ``body.points_on_segments``."""
    return joints.take(segments, 0) + (R.take(segments, 0) @ local)[..., 0]


__all__ = ["Kinematics", "points_on_segments"]
