"""One frame's rotation algebra and forward kinematics on small numpy arrays: the live
poser's per-frame path (``inference/poser/poser.py``, ``Poser.finish``).

Why beside ``rotations`` and ``body``: those run every formula through a back-end shim
so that numpy and torch share one text, and each call converts and broadcasts its inputs.
On a batch that costs nothing; on one frame's 24 segments it is most of the time (a frame
made ~170 tensor conversions before these kernels). Here are the same formulas, in the
same conventions (DESIGN.md: R_WB, 6D = the first two columns, quaternions (w, x, y, z),
rotation vectors), for numpy arrays only, with the index work done once at import.
tests/inference/body/test_frame_kernels.py checks each against its ``rotations`` or
``body`` counterpart.

Every function keeps its input's float dtype (float32 in, float32 out, as the poser's
torch path computed it).
"""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import N_SEGMENTS, PARENTS

_C1 = np.array([1, 2, 0])
_C2 = np.array([2, 0, 1])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (3)."""
    return a.take(_C1, -1) * b.take(_C2, -1) - a.take(_C2, -1) * b.take(_C1, -1)


def _norm(v: np.ndarray) -> np.ndarray:
    """(..., 1) Euclidean norms over the last axis."""
    return np.sqrt((v * v).sum(-1, keepdims=True))


def rot6d_to_matrix(d6: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt, as ``rotations.rot6d_to_matrix``."""
    a1, a2 = d6[..., 0:3], d6[..., 3:6]
    b1 = a1 / _norm(a1)
    b2 = a2 - (b1 * a2).sum(-1, keepdims=True) * b1
    b2 = b2 / _norm(b2)
    out = np.empty((*d6.shape[:-1], 3, 3), dtype=b1.dtype)
    out[..., 0] = b1
    out[..., 1] = b2
    out[..., 2] = cross(b1, b2)
    return out


def matrix_to_rot6d(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 6): the first two columns, as ``rotations.matrix_to_rot6d``."""
    return np.swapaxes(R[..., :, :2], -1, -2).reshape(*R.shape[:-2], 6)


# matrix_to_quat's four candidates (4 q_m q for m = w, x, y, z) as one linear map of the
# nine matrix entries (row-major) plus a constant: cands = r9 @ _QW + _QB
_QW = np.zeros((9, 4, 4))
_QB = np.zeros((4, 4))
for _m, _rows in enumerate([
    [((0, 1), (4, 1), (8, 1)), ((7, 1), (5, -1)), ((2, 1), (6, -1)), ((3, 1), (1, -1))],
    [((7, 1), (5, -1)), ((0, 1), (4, -1), (8, -1)), ((1, 1), (3, 1)), ((2, 1), (6, 1))],
    [((2, 1), (6, -1)), ((1, 1), (3, 1)), ((0, -1), (4, 1), (8, -1)), ((5, 1), (7, 1))],
    [((3, 1), (1, -1)), ((2, 1), (6, 1)), ((5, 1), (7, 1)), ((0, -1), (4, -1), (8, 1))],
]):
    for _c, _terms in enumerate(_rows):
        for _i, _s in _terms:
            _QW[_i, _m, _c] = _s
    _QB[_m, _m] = 1.0
_QW = _QW.reshape(9, 16)
_QB = _QB.reshape(16)
_QW32, _QB32 = _QW.astype(np.float32), _QB.astype(np.float32)
_DIAG = np.arange(4)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) -> (n, 4) with w >= 0, the largest-divisor formula of
    ``rotations.matrix_to_quat``."""
    n = R.shape[0]
    W, B = (_QW32, _QB32) if R.dtype == np.float32 else (_QW, _QB)
    cands = (R.reshape(n, 9) @ W + B).reshape(n, 4, 4)
    best = cands[np.arange(n), np.argmax(cands[:, _DIAG, _DIAG], axis=-1)]
    q = best / _norm(best)
    return np.where(q[:, :1] < 0, -q, q)


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """(..., 4) -> (..., 3) rotation vectors, angle in [0, pi], as ``rotations.quat_to_axis_angle``."""
    q = np.where(q[..., :1] < 0, -q, q)
    w, v = q[..., 0], q[..., 1:]
    n = _norm(v)[..., 0]
    small = n < 1e-4 * w  # else n > 0: w >= 0, and q is not zero
    w_safe = np.where(small, w, 1.0)
    r2 = (n / w_safe) ** 2
    scale = np.where(small, 2.0 / w_safe * (1.0 - r2 / 3.0), 2.0 * np.arctan2(n, w) / np.where(small, 1.0, n))
    return scale[..., None] * v


def so3_log(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) -> (n, 3): ``rotations.so3_log``."""
    return quat_to_axis_angle(matrix_to_quat(R))


# the skew-symmetric [v]_x as a linear map of v: flat (9,) entries = v @ _SKEW
_SKEW = np.zeros((3, 9))
for _k, (_i, _j) in enumerate([(2, 1), (0, 2), (1, 0)]):
    _SKEW[_k, 3 * _i + _j], _SKEW[_k, 3 * _j + _i] = 1.0, -1.0
_SKEW32 = _SKEW.astype(np.float32)
_EYE = np.eye(3)
_EYE32 = _EYE.astype(np.float32)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) -> (..., 3, 3), tolerating non-unit q, as ``rotations.quat_to_matrix``:
    with s = 2 / |q|^2, R = s v v^T + (1 - s |v|^2) I + s w [v]_x (the same entries,
    ``1 - yy - zz`` = ``1 - (xx + yy + zz) + xx``, summed in another order)."""
    f32 = q.dtype == np.float32
    w, v = q[..., :1], q[..., 1:]
    s = 2.0 / (q * q).sum(-1, keepdims=True)
    sv = s * v
    out = sv[..., :, None] * v[..., None, :]  # s v v^T
    out += (1.0 - (sv * v).sum(-1))[..., None, None] * (_EYE32 if f32 else _EYE)
    out += ((sv * w) @ (_SKEW32 if f32 else _SKEW)).reshape(out.shape)
    return out


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3): ``rotations.so3_exp`` (the series near zero included)."""
    th = _norm(rotvec)[..., 0]
    small = th < 1e-4
    th_safe = np.where(small, 1.0, th)
    k = np.where(small, 0.5 - th * th / 48.0, np.sin(0.5 * th_safe) / th_safe)
    q = np.empty((*rotvec.shape[:-1], 4), dtype=rotvec.dtype)
    q[..., 0] = np.cos(0.5 * th)
    q[..., 1:] = k[..., None] * rotvec
    return quat_to_matrix(q)


def matrix_about_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) turns by ``angle`` (...) about the unit ``axis`` (3,): ``rotations.matrix_about_axis``."""
    half = 0.5 * angle
    q = np.empty((*np.shape(angle), 4), dtype=np.result_type(angle, axis))
    q[..., 0] = np.cos(half)
    q[..., 1:] = np.sin(half)[..., None] * axis
    return quat_to_matrix(q)


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


__all__ = ["cross", "rot6d_to_matrix", "matrix_to_rot6d", "matrix_to_quat", "quat_to_axis_angle", "so3_log",
           "quat_to_matrix", "so3_exp", "matrix_about_axis", "Kinematics", "points_on_segments"]
