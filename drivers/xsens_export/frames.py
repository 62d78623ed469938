"""Orientation as Xsens exports write it, turned into our quaternions.

Xsens writes a sensor's orientation as R_GS (sensor -> local Earth frame) in one of three
parameterisations: a quaternion (w first), a rotation matrix Mat[row][col], or Euler
angles in degrees, roll about X, pitch about Y, yaw about Z, composed as
R = Rz(yaw) Ry(pitch) Rx(roll). Checked on the public OpenSim example exports (matrix,
MT Manager) and a DOT export (Euler): turned to Earth by these conventions, the still
sensors' specific force comes out as +9.8 m/s^2 up. The Earth frame is ENU unless the
export says otherwise (MT Manager's ``Coordinate system``: ENU, NED or NWU); all of them
are turned to a Z-up frame here, heading being arbitrary anyway until calibration.

Vectorised numpy; the algebra is ``drivers._math``'s (drivers import nothing of ours).
"""

from __future__ import annotations

import numpy as np

from drivers._math import matrix_to_quat, quat_from_euler_zyx

_H = np.sqrt(0.5)
# q_(ENU <- frame): pre-multiplied, it re-expresses an orientation in a Z-up frame
EARTH_TO_ENU: dict[str, np.ndarray] = {
    "enu": np.array([1.0, 0.0, 0.0, 0.0]),
    "nwu": np.array([_H, 0.0, 0.0, _H]),  # north -> Y, west -> -X: +90 deg about Z
    "ned": np.array([0.0, _H, _H, 0.0]),  # north <-> east swapped, down -> up: 180 deg about (1,1,0)
}


def from_euler_deg(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 4) from Xsens Euler angles in degrees (module docstring for the order)."""
    return quat_from_euler_zyx(yaw, pitch, roll, degrees=True)


def from_matrix(R: np.ndarray) -> np.ndarray:
    """(N, 4) from (N, 3, 3) finite rotation matrices Mat[row][col]."""
    return matrix_to_quat(R)


def normalise(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit quaternions, ok): rows far from unit length (or NaN) are not orientations;
    they stay NaN and ok is False there."""
    n = np.linalg.norm(q, axis=-1)
    ok = np.isfinite(n) & (np.abs(n - 1.0) < 0.5)
    out = np.full_like(q, np.nan)
    out[ok] = q[ok] / n[ok, None]
    return out, ok


__all__ = ["EARTH_TO_ENU", "from_euler_deg", "from_matrix", "normalise"]
