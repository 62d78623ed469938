"""Our world frame to Unity's, for the receivers that live in Unity (VMC apps, VRChat).

Ours (DESIGN.md): right-handed, X forward, Y left, Z up. Unity: left-handed, X right,
Y up, Z forward. One axis map takes vectors across: ``v_U = M v``, ``M`` sending our
forward to Unity +Z, our up to +Y and our left to -X. ``det M = -1``: the handedness
flips, which is why a rotation is not re-expressed by relabelling quaternion components
but by conjugation, ``R_U = M R M^T``; that is again a proper rotation, and Unity's
``Quaternion`` and ``Transform`` use the same algebra (Hamilton product, column vectors)
as ours, so its quaternion is our ``matrix_to_quat`` of ``R_U`` with the components
re-ordered to Unity's (x, y, z, w). In components this is
``(x, y, z, w)_U = (q_y, -q_z, -q_x, q_w)``: the vector part of a quaternion is an axial
vector and picks up ``det M`` (ROS's FLU -> Unity's RUF conversion gives the same up to
the overall sign). See docs/streams.md.
"""

from __future__ import annotations

import numpy as np

from inference.body.rotations import matrix_to_euler, matrix_to_quat

# rows: Unity x = -our y, Unity y = our z, Unity z = our x
M_UNITY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def vec_to_unity(v: np.ndarray) -> np.ndarray:
    """Positions or directions (..., 3), our frame -> Unity's."""
    return np.asarray(v, dtype=np.float64) @ M_UNITY.T


def rot_to_unity(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3), our frame -> Unity's (by conjugation, see module doc)."""
    return M_UNITY @ np.asarray(R, dtype=np.float64) @ M_UNITY.T


def unity_quat(R_unity: np.ndarray) -> np.ndarray:
    """(..., 4) quaternion in Unity's component order (x, y, z, w) of a Unity-frame matrix."""
    q = matrix_to_quat(R_unity)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def unity_euler_deg(R_unity: np.ndarray) -> np.ndarray:
    """(..., 3) Euler angles (x, y, z) in degrees as Unity's ``Transform.eulerAngles`` reads
    them: rotate about Z, then X, then Y (world axes), i.e. ``R = Ry(y) Rx(x) Rz(z)``,
    which is our intrinsic "YXZ"."""
    yxz = matrix_to_euler(R_unity, "YXZ")
    return np.rad2deg(yxz[..., [1, 0, 2]])
