"""The drivers' quaternion algebra: their one copy, because drivers may not import inference.

DESIGN.md's layering has ``drivers`` import nothing of ours (so a driver can be lifted
into another program, and the wire formats never depend on the model), so the drivers
cannot use ``inference.body.conventions``. Everything a driver needs is here, once, in
the same conventions: quaternions scalar-first (w, x, y, z), Hamilton product, unit,
turning the sensor frame into the world frame (R_WS), float64. Where scipy has the
operation, it does the work (``scipy.spatial.transform.Rotation``, xyzw inside, crossed
only in ``_to_scipy``/``_from_scipy``); the products and the rotation of a vector are a
few lines of numpy, vectorised over leading axes, cheap enough per packet.

``tests/drivers/test_frames.py`` checks these against packets decoded by hand and
``tests/inference/body/test_conventions.py`` checks the inference side against scipy,
so the two copies cannot drift apart unnoticed.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

G = 9.80665  # standard gravity, m/s^2; what "1 g" means in device units


def _to_scipy(q: np.ndarray) -> Rotation:
    q = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat(q[..., [1, 2, 3, 0]].reshape(-1, 4) if q.ndim > 1 else q[[1, 2, 3, 0]])


def _from_scipy(rot: Rotation, shape: tuple[int, ...]) -> np.ndarray:
    return np.asarray(rot.as_quat())[..., [3, 0, 1, 2]].reshape(*shape, 4)


def quat_from_euler_zyx(yaw, pitch, roll, degrees: bool = False) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) as quaternions (..., 4): the aerospace order yaw,
    then pitch, then roll, that the BNO08x RVC datasheet and Xsens's Euler exports use."""
    yaw, pitch, roll = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (yaw, pitch, roll)))
    angles = np.stack([yaw, pitch, roll], axis=-1)
    return _from_scipy(Rotation.from_euler("ZYX", angles.reshape(-1, 3), degrees=degrees), yaw.shape)


def euler_zyx_from_quat(q: np.ndarray) -> tuple[float, float, float]:
    """Inverse of ``quat_from_euler_zyx`` for one quaternion: (yaw, pitch, roll) in radians
    (pitch clamped at +-90 deg, where yaw and roll share one axis)."""
    w, x, y, z = (float(v) for v in q)
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    return yaw, pitch, roll


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of (..., 4) quaternions: b first, then a (like ``A @ B``)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """The inverse rotation of unit quaternions (..., 4): world -> sensor for R_WS."""
    return np.asarray(q, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors v (..., 3) of the sensor frame in the world frame: ``R(q) @ v`` for unit q."""
    q, v = np.asarray(q, dtype=np.float64), np.asarray(v, dtype=np.float64)
    u, w = q[..., 1:], q[..., :1]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 3, 3) R_WS of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    return _to_scipy(q).as_matrix().reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions of rotation matrices (..., 3, 3) (finite; a matrix a little off
    orthonormal, as text exports round them, gives the nearest rotation's)."""
    R = np.asarray(R, dtype=np.float64)
    return _from_scipy(Rotation.from_matrix(R.reshape(-1, 3, 3)), R.shape[:-2])


def quat_log(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of unit quaternions (..., 4), the shorter way round."""
    q = np.asarray(q, dtype=np.float64)
    return _to_scipy(q).as_rotvec().reshape(*q.shape[:-1], 3)


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """One quaternion scaled to unit length with w >= 0; identity if it has no length."""
    n = float(np.sqrt(np.dot(q, q)))
    if not math.isfinite(n) or n < 1e-9:
        return np.array([1.0, 0.0, 0.0, 0.0])
    q = q / n
    return q if q[0] >= 0 else -q
