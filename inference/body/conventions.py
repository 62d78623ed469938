"""The project's rotation conventions, once, over ``scipy.spatial.transform.Rotation``.

Why this module exists: the same few pieces of geometry (the heading of a rotation
matrix, a turn about the vertical, wxyz <-> scipy's xyzw) were written by hand in many
modules, each a chance to get a sign or a component order wrong. Here they are written
once, in the conventions of DESIGN.md, and everything numpy that needs them imports them:

- quaternions are (w, x, y, z), unit, float64; scipy's are (x, y, z, w), so every
  crossing goes through ``to_scipy`` / ``from_scipy`` and nothing else;
- a rotation matrix maps body to world (R_WB), world Z is up, so "yaw" and "heading"
  are angles about world Z, counter-clockwise seen from above, in radians;
- any leading batch shape, broadcast like numpy.

How it relates to ``inference.body.rotations``: that module is the numpy/torch-generic
algebra the network and its training need (6D, differentiable log/exp on tensors, one
formula for both back ends). This one is the float64 numpy side of the same algebra: the
conventions, built on scipy (tested, fast, and the reference our own formulas are
checked against), for code that never touches a tensor. Code outside the network should
reach for this module first, and for ``rotations`` only where a tensor may arrive or a
conversion it alone has (6D, Euler orders of BVH) is needed. ``drivers`` cannot import
either (layering: drivers import nothing of ours); ``drivers/_math.py`` is its own copy.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "to_scipy", "from_scipy", "quat_to_matrix", "matrix_to_quat",
    "yaw_of", "quat_yaw", "rot_z", "quat_z", "heading_of", "heading_vector", "forward_xy",
    "turn_xy", "turn_cs", "wrap_angle", "mean_angle", "swing_twist_z", "without_yaw",
]

_Z = np.array([0.0, 0.0, 1.0])


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


# --------------------------------------------------------------------------- scipy crossing
def to_scipy(q) -> Rotation:
    """A scipy ``Rotation`` (a flat stack when q has more than one leading axis) from
    wxyz quaternions (..., 4). Reshape its outputs with ``q.shape[:-1]``."""
    q = _f64(q)
    return Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]] if q.ndim > 1 else q[[1, 2, 3, 0]])


def from_scipy(rot: Rotation, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """wxyz quaternions (w >= 0) of a scipy ``Rotation``, reshaped to ``shape + (4,)`` if given."""
    q = np.asarray(rot.as_quat())[..., [3, 0, 1, 2]]
    q = np.where(q[..., :1] < 0, -q, q)
    return q if shape is None else q.reshape(*shape, 4)


def quat_to_matrix(q) -> np.ndarray:
    """(..., 3, 3) R_WB of unit wxyz quaternions (..., 4), via scipy."""
    q = _f64(q)
    return to_scipy(q).as_matrix().reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R) -> np.ndarray:
    """(..., 4) wxyz quaternions (w >= 0) of rotation matrices (..., 3, 3), via scipy."""
    R = _f64(R)
    rot = Rotation.from_matrix(R.reshape(-1, 3, 3) if R.ndim > 2 else R)
    return from_scipy(rot, R.shape[:-2])


# --------------------------------------------------------------------------- about world Z
def yaw_of(R) -> np.ndarray:
    """Heading (rad, about world Z) of rotation matrices (..., 3, 3).

    ``arctan2(R10 - R01, R00 + R11)``: the angle of the rotation about Z nearest to R
    (least squares), which is also the twist about Z of R's swing-twist decomposition
    (``2 atan2(z, w)`` of its quaternion). Exact for a pure turn about Z; for a tilted
    R it is robust where the heading of one axis is not. Works as well on any
    ``M = sum a b^T``: then it is the turn about Z that best carries the b onto the a.
    """
    R = _f64(R)
    return np.arctan2(R[..., 1, 0] - R[..., 0, 1], R[..., 0, 0] + R[..., 1, 1])


def quat_yaw(q) -> np.ndarray:
    """``yaw_of`` of wxyz quaternions (..., 4), without building the matrix."""
    q = _f64(q)
    w, z = q[..., 0], q[..., 3]
    return np.arctan2(2.0 * w * z, w * w - z * z)


def rot_z(angle) -> np.ndarray:
    """(..., 3, 3) the turn by ``angle`` (rad, counter-clockwise from above) about world Z."""
    a = _f64(angle)
    rot = Rotation.from_rotvec(a.reshape(-1, 1) * _Z)
    return rot.as_matrix().reshape(*a.shape, 3, 3)


def quat_z(angle) -> np.ndarray:
    """(..., 4) wxyz quaternion of ``rot_z(angle)``: (cos a/2, 0, 0, sin a/2)."""
    a = _f64(angle)
    rot = Rotation.from_rotvec(a.reshape(-1, 1) * _Z)
    q = np.asarray(rot.as_quat())[:, [3, 0, 1, 2]]  # keep the sign: quat_z(a) is continuous in a
    return q.reshape(*a.shape, 4)


def heading_of(v) -> np.ndarray:
    """Heading (rad) of vectors (..., 2 or 3): the angle of their ground-plane part from X."""
    v = _f64(v)
    return np.arctan2(v[..., 1], v[..., 0])


def heading_vector(angle) -> np.ndarray:
    """(..., 3) the horizontal unit vector of a heading: (cos a, sin a, 0)."""
    a = _f64(angle)
    return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=-1)


def forward_xy(R, axis: int = 0) -> np.ndarray:
    """(..., 2) the unit ground-plane direction of R's body ``axis`` (X: forward) in the world;
    NaN where that axis is vertical."""
    v = _f64(R)[..., :2, axis]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 1e-12, v / n, np.nan)


def turn_xy(v, angle) -> np.ndarray:
    """(..., 2) ground-plane vectors turned by ``angle`` (rad) about Z (negative: turned back)."""
    a = _f64(angle)
    return turn_cs(_f64(v), np.cos(a), np.sin(a))


def turn_cs(v: np.ndarray, c, s) -> np.ndarray:
    """Vectors v (..., 2 or 3) turned about world Z by the angle whose cosine and sine are
    ``c``, ``s`` (broadcast against ``v[..., 0]``), z kept, in the inputs' own dtype: for
    per-frame code that holds the cosine and sine already (the live poser's heading frames,
    float32) and would pay for a rotation object or a float64 round trip."""
    x, y = v[..., 0], v[..., 1]
    tx = c * x - s * y
    out = np.empty((*tx.shape, v.shape[-1]), dtype=tx.dtype)
    out[..., 0] = tx
    out[..., 1] = s * x + c * y
    if v.shape[-1] == 3:
        out[..., 2] = v[..., 2]
    return out


def wrap_angle(a) -> np.ndarray:
    """Angles wrapped into [-pi, pi)."""
    return (_f64(a) + np.pi) % (2.0 * np.pi) - np.pi


def mean_angle(a, axis=None) -> np.ndarray:
    """Circular mean of angles (rad): the heading of the mean of their unit vectors."""
    a = _f64(a)
    return np.arctan2(np.sin(a).mean(axis=axis), np.cos(a).mean(axis=axis))


def swing_twist_z(R) -> tuple[np.ndarray, np.ndarray]:
    """Split R (..., 3, 3) = twist @ swing: ``twist`` = ``rot_z(yaw_of(R))`` about world Z and
    ``swing`` the rest, a rotation about a horizontal axis (its yaw is zero)."""
    twist = rot_z(yaw_of(R))
    return twist, np.swapaxes(twist, -1, -2) @ _f64(R)


def without_yaw(R) -> np.ndarray:
    """R with its heading taken away: ``rot_z(-yaw_of(R)) @ R`` (the swing of ``swing_twist_z``)."""
    return swing_twist_z(R)[1]
