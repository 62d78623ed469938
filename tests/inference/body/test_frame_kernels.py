"""The one-frame numpy kernels (``rotations``' ``*_np`` and ``frame_kernels``' FK) give what
the general rotation algebra and FK give, in float32 and float64, at the corner cases the
general code guards (tiny and near-pi angles)."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body import conventions as C
from inference.body import frame_kernels as fk
from inference.body import rotations as rot
from inference.body.body import CONTACT_SEGMENTS, Body, contact_points, forward_kinematics


def _tol(dtype) -> float:
    return 2e-6 if dtype == np.float32 else 1e-12


def _rotvecs(rng, n: int, dtype) -> np.ndarray:
    """Random rotation vectors, with tiny angles, zero, and angles near pi among them."""
    v = rng.normal(size=(n, 3))
    v[: n // 4] *= 1e-6
    v[n // 4] = 0.0
    axis = v[n // 2:] / np.linalg.norm(v[n // 2:], axis=-1, keepdims=True)
    v[n // 2:] = axis * (np.pi - rng.uniform(1e-3, 0.1, size=(n - n // 2, 1)))
    return v.astype(dtype)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernels_match_the_rotation_algebra(dtype):
    rng = np.random.default_rng(0)
    tol = _tol(dtype)
    d6 = rng.normal(size=(5, 24, 6)).astype(dtype)
    R = rot.rot6d_to_matrix_np(d6)
    assert R.dtype == dtype
    np.testing.assert_allclose(R, rot.rot6d_to_matrix(d6), atol=tol)
    np.testing.assert_allclose(rot.matrix_to_rot6d_np(R), rot.matrix_to_rot6d(R), atol=0)
    v = _rotvecs(rng, 40, dtype)
    Rv = rot.so3_exp(v)
    np.testing.assert_allclose(rot.matrix_to_quat_np(Rv), rot.matrix_to_quat(Rv), atol=tol)
    np.testing.assert_allclose(rot.so3_log_np(Rv), rot.so3_log(Rv), atol=tol * 10)
    q = rng.normal(size=(7, 4)).astype(dtype)  # not unit: both divide by |q|^2
    np.testing.assert_allclose(rot.quat_to_matrix_np(q), rot.quat_to_matrix(q), atol=tol)
    np.testing.assert_allclose(rot.quat_to_axis_angle_np(q), rot.quat_to_axis_angle(q), atol=tol * 10)
    unit = rot.quat_normalize(q, positive_w=True)
    t = rng.uniform(0.0, 1.0, size=(7,)).astype(dtype)
    np.testing.assert_allclose(rot.quat_power_np(unit, t), rot.quat_exp(t[:, None] * rot.quat_log(unit)), atol=tol * 10)
    axis, angle = np.array([0.0, 1.0, 0.0], dtype), rng.normal(size=(3,)).astype(dtype)
    np.testing.assert_allclose(rot.matrix_about_axis_np(axis, angle),
                               rot.matrix_about_axis(np.broadcast_to(axis, (3, 3)), angle), atol=tol)


def test_heading_turns_match_the_rotation_matrices():
    rng = np.random.default_rng(2)
    h = rng.normal(size=(9, 2))
    Rz = rot.facing_x(h)
    np.testing.assert_allclose(Rz, C.rot_z(-C.heading_of(h)), atol=1e-12)
    v = rng.normal(size=(9, 3))
    yaw = C.heading_of(h)
    np.testing.assert_allclose(C.turn_cs(v, np.cos(yaw), -np.sin(yaw)), (Rz @ v[..., None])[..., 0], atol=1e-12)
    v32 = v.astype(np.float32)
    c32, s32 = np.cos(yaw).astype(np.float32), np.sin(yaw).astype(np.float32)
    assert C.turn_cs(v32, c32, s32).dtype == np.float32


def test_kinematics_match_forward_kinematics_and_contact_points():
    rng = np.random.default_rng(1)
    body = Body.from_height(1.62)
    R = rot.so3_exp(rng.normal(size=(24, 3)))
    kin = fk.Kinematics(body.offsets, dtype=np.float64)
    joints = kin.joints(R)
    np.testing.assert_allclose(joints, forward_kinematics(R, np.zeros(3), body.offsets), atol=1e-12)
    local = np.asarray(body.contact_offsets)[:, :, None]
    np.testing.assert_allclose(fk.points_on_segments(R, joints, np.array(CONTACT_SEGMENTS), local),
                               contact_points(R, joints, body), atol=1e-12)
    R32 = R.astype(np.float32)
    j32 = fk.Kinematics(body.offsets).joints(R32)
    assert j32.dtype == np.float32
    np.testing.assert_allclose(j32, joints, atol=1e-5)
