"""inference.body.conventions against scipy on random rotations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from inference.body import conventions as C
from inference.body import rotations as rot


@pytest.fixture
def rng():
    return np.random.default_rng(48)


def test_wxyz_order_crossing_scipy():
    # 90 deg about x: scipy says (x, y, z, w) = (s, 0, 0, c), we say (c, s, 0, 0)
    s = np.sqrt(0.5)
    q = np.array([s, s, 0.0, 0.0])
    np.testing.assert_allclose(C.to_scipy(q).as_quat(), [s, 0.0, 0.0, s])
    np.testing.assert_allclose(C.from_scipy(Rotation.from_rotvec([np.pi / 2, 0, 0])), q, atol=1e-15)
    np.testing.assert_allclose(C.quat_to_matrix(q) @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-15)


def test_quat_matrix_round_trips_match_scipy_and_rotations(rng):
    q = rot.random_quat((6, 5), rng)
    R = C.quat_to_matrix(q)
    assert R.shape == (6, 5, 3, 3)
    ref = Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(6, 5, 3, 3)
    np.testing.assert_allclose(R, ref, atol=1e-14)
    np.testing.assert_allclose(R, rot.quat_to_matrix(q), atol=1e-14)
    back = C.matrix_to_quat(R)
    assert back.shape == (6, 5, 4) and np.all(back[..., 0] >= 0)
    np.testing.assert_allclose(back, q, atol=1e-13)
    np.testing.assert_allclose(C.from_scipy(C.to_scipy(q), q.shape[:-1]), q, atol=1e-15)
    # a single rotation keeps its shape too
    assert C.quat_to_matrix(q[0, 0]).shape == (3, 3) and C.matrix_to_quat(R[0, 0]).shape == (4,)


def test_yaw_of_rot_z_is_the_angle(rng):
    a = rng.uniform(-np.pi, np.pi, (4, 3))
    Rz = C.rot_z(a)
    assert Rz.shape == (4, 3, 3, 3)
    ref = Rotation.from_euler("z", a.reshape(-1, 1)).as_matrix().reshape(4, 3, 3, 3)
    np.testing.assert_allclose(Rz, ref, atol=1e-15)
    np.testing.assert_allclose(C.yaw_of(Rz), a, atol=1e-13)
    np.testing.assert_allclose(C.quat_to_matrix(C.quat_z(a)), Rz, atol=1e-15)
    np.testing.assert_allclose(C.quat_yaw(C.quat_z(a)), a, atol=1e-13)
    np.testing.assert_allclose(C.quat_z(0.5), [np.cos(0.25), 0.0, 0.0, np.sin(0.25)])
    assert C.rot_z(0.5).shape == (3, 3)


def test_yaw_of_tilt_then_yaw(rng):
    """A tilt about a horizontal axis (up to 60 deg), then a turn about Z: the yaw is the turn."""
    n = 200
    a = rng.uniform(-np.pi, np.pi, n)
    axis = np.concatenate([rng.normal(size=(n, 2)), np.zeros((n, 1))], axis=1)
    tilt = Rotation.from_rotvec(axis / np.linalg.norm(axis, axis=1, keepdims=True)
                                * rng.uniform(0, np.pi / 3, (n, 1))).as_matrix()
    R = C.rot_z(a) @ tilt
    # a tilt about any horizontal axis has no twist about Z
    np.testing.assert_allclose(C.yaw_of(tilt), 0.0, atol=1e-13)
    np.testing.assert_allclose(C.yaw_of(R), a, atol=1e-12)
    np.testing.assert_allclose(C.quat_yaw(C.matrix_to_quat(R)), a, atol=1e-12)
    twist, swing = C.swing_twist_z(R)
    np.testing.assert_allclose(twist, C.rot_z(a), atol=1e-12)
    np.testing.assert_allclose(swing, tilt, atol=1e-12)
    np.testing.assert_allclose(C.without_yaw(R), tilt, atol=1e-12)


def test_yaw_of_is_the_least_squares_turn(rng):
    """On M = sum a b^T, yaw_of is the turn about Z that best carries the b onto the a."""
    b = rng.normal(size=(50, 3))
    a = b @ C.rot_z(0.7).T + 0.01 * rng.normal(size=(50, 3))
    M = a.T @ b
    yaws = np.linspace(-np.pi, np.pi, 20001)
    cost = [np.sum((a - b @ C.rot_z(y).T) ** 2) for y in yaws]
    assert abs(C.yaw_of(M) - yaws[int(np.argmin(cost))]) < 1e-3


def test_headings(rng):
    a = rng.uniform(-np.pi, np.pi, 10)
    v = C.heading_vector(a)
    np.testing.assert_allclose(C.heading_of(v), a, atol=1e-14)
    np.testing.assert_allclose(C.heading_of(v[:, :2]), a, atol=1e-14)
    np.testing.assert_allclose(v, (C.rot_z(a) @ [1.0, 0.0, 0.0]), atol=1e-15)
    np.testing.assert_allclose(C.forward_xy(C.rot_z(a)), v[:, :2], atol=1e-15)
    np.testing.assert_allclose(C.turn_xy(v[:, :2], -a), np.tile([1.0, 0.0], (10, 1)), atol=1e-14)
    np.testing.assert_allclose(C.turn_xy([1.0, 0.0], np.pi / 2), [0.0, 1.0], atol=1e-15)
    assert np.all(np.isnan(C.forward_xy(Rotation.from_rotvec([0, -np.pi / 2, 0]).as_matrix())))
    np.testing.assert_allclose(C.wrap_angle(a + 4 * np.pi), a, atol=1e-12)
    assert abs(C.wrap_angle(C.mean_angle([np.pi - 0.1, -np.pi + 0.1]) + np.pi)) < 1e-12


def test_turns_of_vectors_match_scipy(rng):
    a = rng.uniform(-np.pi, np.pi, 12)
    v = rng.normal(size=(12, 3))
    ref = Rotation.from_rotvec(a[:, None] * [0.0, 0.0, 1.0]).apply(v)
    np.testing.assert_allclose(C.turn_cs(v, np.cos(a), np.sin(a)), ref, atol=1e-14)
    np.testing.assert_allclose(C.turn_xy(v[:, :2], a), ref[:, :2], atol=1e-14)
    h = rng.normal(size=(12, 2))  # facing_x turns each direction onto +X, numpy or torch alike
    face = rot.facing_x(h)
    np.testing.assert_allclose(face, Rotation.from_rotvec(-C.heading_of(h)[:, None] * [0.0, 0.0, 1.0]).as_matrix(),
                               atol=1e-14)
    np.testing.assert_allclose((face @ np.c_[h, np.zeros(12)][..., None])[:, 1:, 0], 0.0, atol=1e-14)
