"""Orientation as Xsens exports write it, turned into our quaternions.

Xsens writes a sensor's orientation as R_GS (sensor -> local Earth frame) in one of three
parameterisations: a quaternion (w first), a rotation matrix Mat[row][col], or Euler
angles in degrees, roll about X, pitch about Y, yaw about Z, composed as
R = Rz(yaw) Ry(pitch) Rx(roll). Checked on the public OpenSim example exports (matrix,
MT Manager) and a DOT export (Euler): turned to Earth by these conventions, the still
sensors' specific force comes out as +9.8 m/s^2 up. The Earth frame is ENU unless the
export says otherwise (MT Manager's ``Coordinate system``: ENU, NED or NWU); all of them
are turned to a Z-up frame here, heading being arbitrary anyway until calibration.

Vectorised numpy only: drivers import nothing of ours.
"""

from __future__ import annotations

import numpy as np

_H = np.sqrt(0.5)
# q_(ENU <- frame): pre-multiplied, it re-expresses an orientation in a Z-up frame
EARTH_TO_ENU: dict[str, np.ndarray] = {
    "enu": np.array([1.0, 0.0, 0.0, 0.0]),
    "nwu": np.array([_H, 0.0, 0.0, _H]),  # north -> Y, west -> -X: +90 deg about Z
    "ned": np.array([0.0, _H, _H, 0.0]),  # north <-> east swapped, down -> up: 180 deg about (1,1,0)
}


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions (w first)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors v turned by unit quaternions q (sensor -> Earth for R_GS)."""
    u, w = q[..., 1:], q[..., :1]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def from_euler_deg(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 4) from Xsens Euler angles in degrees (module docstring for the order)."""
    r, p, y = (np.deg2rad(np.asarray(a, dtype=np.float64)) / 2 for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([cr * cp * cy + sr * sp * sy,
                     sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy], axis=-1)


def from_matrix(R: np.ndarray) -> np.ndarray:
    """(N, 4) from (N, 3, 3) rotation matrices, by the largest of the four candidate
    pivots (numerically safe for any rotation)."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    trace = m00 + m11 + m22
    piv = np.stack([trace, m00, m11, m22], axis=1)
    k = np.argmax(np.nan_to_num(piv, nan=-np.inf), axis=1)
    q = np.empty((len(R), 4))
    s = np.sqrt(np.maximum(1.0 + 2.0 * piv[np.arange(len(R)), k] - trace, 1e-12)) * 2.0  # 4 * |component|
    d = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    o = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    cases = {
        0: (s / 4, d[0] / s, d[1] / s, d[2] / s),
        1: (d[0] / s, s / 4, o[0] / s, o[1] / s),
        2: (d[1] / s, o[0] / s, s / 4, o[2] / s),
        3: (d[2] / s, o[1] / s, o[2] / s, s / 4),
    }
    for case, comps in cases.items():
        sel = k == case
        q[sel] = np.stack(comps, axis=1)[sel]
    return q


def normalise(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit quaternions, ok): rows far from unit length (or NaN) are not orientations;
    they stay NaN and ok is False there."""
    n = np.linalg.norm(q, axis=-1)
    ok = np.isfinite(n) & (np.abs(n - 1.0) < 0.5)
    out = np.full_like(q, np.nan)
    out[ok] = q[ok] / n[ok, None]
    return out, ok


__all__ = ["EARTH_TO_ENU", "quat_mul", "rotate", "conjugate", "from_euler_deg", "from_matrix", "normalise"]
