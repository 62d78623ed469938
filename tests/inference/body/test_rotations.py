"""Tests for inference.rotations: conventions against scipy, back-end agreement, edge cases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation, Slerp

from inference.body import rotations as rot

RNG_SEED = 1234
TB_ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
PROPER_ORDERS = ["XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ"]
ALL_ORDERS = TB_ORDERS + PROPER_ORDERS + [o.lower() for o in TB_ORDERS + PROPER_ORDERS]
REPS = ["quat", "matrix", "rot6d", "axis_angle", "euler"]
EULER_ORDER = "ZXY"

settings.register_profile("rotations", max_examples=50, deadline=None)
settings.load_profile("rotations")


def rng() -> np.random.Generator:
    return np.random.default_rng(RNG_SEED)


def scipy_rot(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(q)[..., [1, 2, 3, 0]])


def from_scipy(r: Rotation) -> np.ndarray:
    return r.as_quat()[..., [3, 0, 1, 2]]


def same_rotation(q1: np.ndarray, q2: np.ndarray, tol: float = 1e-9) -> None:
    assert np.max(rot.quat_angle_between(q1, q2)) < tol


def call(name: str, x, order: str = EULER_ORDER):
    f = getattr(rot, name)
    return f(x, order) if "euler" in name else f(x)


def encode(rep: str, q: np.ndarray):
    return q if rep == "quat" else call(f"quat_to_{rep}", q)


def decode_matrix(rep: str, x) -> np.ndarray:
    return x if rep == "matrix" else call(f"{rep}_to_matrix", x)


unit_quats = arrays(np.float64, (4,), elements=st.floats(-1, 1)).filter(
    lambda v: np.linalg.norm(v) > 0.1).map(lambda v: v / np.linalg.norm(v))


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("src,dst", [p for p in itertools.permutations(REPS, 2)])
def test_every_pair_round_trips(src: str, dst: str) -> None:
    q = rot.random_quat((5, 7), rng())
    R = rot.quat_to_matrix(q)
    x_src = encode(src, q)
    x_dst = call(f"{src}_to_{dst}", x_src)
    np.testing.assert_allclose(decode_matrix(dst, x_dst), R, atol=1e-12)
    back = call(f"{dst}_to_{src}", x_dst)
    np.testing.assert_allclose(decode_matrix(src, back), R, atol=1e-12)
    assert back.shape == x_src.shape


@given(unit_quats)
def test_values_round_trip_exactly(q: np.ndarray) -> None:
    q = rot.quat_normalize(q, positive_w=True)
    back = rot.matrix_to_quat(rot.quat_to_matrix(q))
    if q[0] < 1e-9:  # a half turn: q and -q both have w = 0
        back = back * np.sign(back @ q)
    np.testing.assert_allclose(back, q, atol=1e-12)
    rv = rot.quat_to_axis_angle(q)
    rv_back = rot.quat_to_axis_angle(rot.axis_angle_to_quat(rv))
    if np.linalg.norm(rv) > np.pi - 1e-9:  # a half turn about u equals one about -u
        rv_back = rv_back * np.sign(rv_back @ rv)
    np.testing.assert_allclose(rv_back, rv, atol=1e-12)
    d6 = rot.quat_to_rot6d(q)
    np.testing.assert_allclose(rot.matrix_to_rot6d(rot.rot6d_to_matrix(d6)), d6, atol=1e-12)
    for order in ("ZXY", "zxy", "ZXZ"):
        e = rot.quat_to_euler(q, order)
        if np.min(np.abs(np.array([np.pi / 2, 0, np.pi]) - np.abs(e[1]))) < 1e-6:
            continue  # gimbal lock: the angles are not unique, test_gimbal_lock covers it
        diff = rot.matrix_to_euler(rot.euler_to_matrix(e, order), order) - e
        np.testing.assert_allclose(np.angle(np.exp(1j * diff)), 0, atol=1e-8)  # pi and -pi are equal


# ----------------------------------------------------------------------------- scipy agreement
def test_matrix_quat_rotvec_agree_with_scipy() -> None:
    q = rot.random_quat(500, rng())
    r = scipy_rot(q)
    np.testing.assert_allclose(rot.quat_to_matrix(q), r.as_matrix(), atol=1e-14)
    np.testing.assert_allclose(rot.quat_to_axis_angle(q), r.as_rotvec(), atol=1e-13)
    np.testing.assert_allclose(rot.axis_angle_to_quat(r.as_rotvec()), q, atol=1e-13)
    same_rotation(rot.matrix_to_quat(r.as_matrix()), q)
    np.testing.assert_allclose(rot.matrix_to_rot6d(r.as_matrix()),
                               np.concatenate([r.as_matrix()[:, :, 0], r.as_matrix()[:, :, 1]], -1))


@pytest.mark.parametrize("order", ALL_ORDERS)
def test_euler_agrees_with_scipy(order: str) -> None:
    q = rot.random_quat(300, rng())
    r = scipy_rot(q)
    np.testing.assert_allclose(rot.quat_to_euler(q, order), r.as_euler(order), atol=1e-10)
    angles = rng().uniform(-np.pi, np.pi, (300, 3))
    np.testing.assert_allclose(rot.euler_to_matrix(angles, order),
                               Rotation.from_euler(order, angles).as_matrix(), atol=1e-14)


def test_bvh_intrinsic_order_is_matrix_product() -> None:
    a, b, c = 0.3, -1.1, 2.0
    R = rot.euler_to_matrix(np.array([a, b, c]), "ZXY")
    Rz = rot.matrix_about_axis([0, 0, 1], a)
    Rx = rot.matrix_about_axis([1, 0, 0], b)
    Ry = rot.matrix_about_axis([0, 1, 0], c)
    np.testing.assert_allclose(R, Rz @ Rx @ Ry, atol=1e-15)
    np.testing.assert_allclose(rot.euler_to_matrix(np.array([a, b, c]), "zxy"), Ry @ Rx @ Rz, atol=1e-15)


def test_operations_agree_with_scipy() -> None:
    g = rng()
    q1, q2 = rot.random_quat(200, g), rot.random_quat(200, g)
    v = g.standard_normal((200, 3))
    r1, r2 = scipy_rot(q1), scipy_rot(q2)
    same_rotation(rot.quat_multiply(q1, q2), from_scipy(r1 * r2))
    np.testing.assert_allclose(rot.quat_rotate(q1, v), r1.apply(v), atol=1e-13)
    same_rotation(rot.quat_inverse(q1), from_scipy(r1.inv()))
    np.testing.assert_allclose(rot.quat_angle_between(q1, q2), (r1.inv() * r2).magnitude(), atol=1e-12)
    t = g.uniform(0, 1, 50)
    ours = rot.quat_slerp(q1[0], q2[0], t)
    theirs = Slerp([0, 1], scipy_rot(np.stack([q1[0], q2[0]])))(t)
    same_rotation(ours, from_scipy(theirs), tol=1e-12)


# ----------------------------------------------------------------------------- numpy vs torch
def _torch_cases():
    g = rng()
    q, q2 = rot.random_quat((3, 4), g), rot.random_quat((3, 4), g)
    R = rot.quat_to_matrix(q)
    v, v2 = g.standard_normal((3, 4, 3)), g.standard_normal((3, 4, 3))
    d6 = g.standard_normal((3, 4, 6))
    rv = rot.quat_to_axis_angle(q)
    eul = rot.quat_to_euler(q, "ZXY")
    t = g.uniform(0, 1, (3, 4))
    cases = [
        ("quat_normalize", (q * 3,)), ("quat_conjugate", (q,)), ("quat_inverse", (q * 2,)),
        ("quat_multiply", (q, q2)), ("quat_rotate", (q, v)), ("quat_to_matrix", (q,)),
        ("matrix_to_quat", (R,)), ("matrix_to_rot6d", (R,)), ("rot6d_to_matrix", (d6,)),
        ("axis_angle_to_quat", (rv,)), ("quat_to_axis_angle", (q,)), ("quat_exp", (rv,)),
        ("quat_log", (q,)), ("so3_exp", (rv,)), ("so3_log", (R,)), ("skew", (v,)),
        ("quat_about_axis", (v, t)), ("matrix_about_axis", (v, t)),
        ("quat_angle_between", (q, q2)), ("matrix_angle_between", (R, rot.quat_to_matrix(q2))),
        ("quat_slerp", (q, q2, t)), ("quat_between_vectors", (v, v2)), ("triad", (v, v2, v2, v)),
    ]
    for order in ("ZXY", "xyz", "ZXZ"):
        cases += [(f"euler_to_quat/{order}", (eul,)), (f"matrix_to_euler/{order}", (R,))]
    for src, dst in itertools.permutations(REPS, 2):
        x = {"quat": q, "matrix": R, "rot6d": d6, "axis_angle": rv, "euler": eul}[src]
        cases.append((f"{src}_to_{dst}", (x,)))
    return cases


def _run(name: str, args):
    fname, _, order = name.partition("/")
    f = getattr(rot, fname)
    if order or "euler" in fname:
        return f(*args, order or EULER_ORDER)
    return f(*args)


@pytest.mark.parametrize("name,args", _torch_cases(), ids=[c[0] for c in _torch_cases()])
def test_numpy_and_torch_agree(name: str, args) -> None:
    out_np = _run(name, args)
    out_t = _run(name, tuple(torch.from_numpy(np.asarray(a)) for a in args))
    assert isinstance(out_np, np.ndarray) and isinstance(out_t, torch.Tensor)
    assert out_t.dtype == torch.float64
    np.testing.assert_allclose(out_t.numpy(), out_np, rtol=0, atol=1e-10)
    out32 = _run(name, tuple(torch.from_numpy(np.asarray(a)).float() for a in args))
    assert out32.dtype == torch.float32


def test_mixed_inputs_follow_the_tensor() -> None:
    q = torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float32)
    out = rot.quat_rotate(q, [1.0, 2.0, 3.0])
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert isinstance(rot.quat_rotate([1.0, 0, 0, 0], [[1, 2, 3]]), np.ndarray)
    assert rot.quat_identity((2,), like=q).dtype == torch.float32
    np.testing.assert_array_equal(rot.quat_identity((2, 3)), np.tile([1.0, 0, 0, 0], (2, 3, 1)))


@pytest.mark.parametrize("fname,shape", [
    ("rot6d_to_matrix", (2, 6)), ("matrix_to_rot6d", (2, 3, 3)), ("quat_to_matrix", (2, 4)),
    ("matrix_to_quat", None), ("axis_angle_to_quat", (2, 3)), ("quat_to_axis_angle", (2, 4)),
])
def test_torch_gradients(fname: str, shape) -> None:
    g = rng()
    if shape is None:
        x = rot.quat_to_matrix(rot.random_quat(2, g))
    else:
        x = g.standard_normal(shape)
    xt = torch.tensor(x, requires_grad=True)
    assert torch.autograd.gradcheck(getattr(rot, fname), (xt,))


def test_gradients_finite_at_identity() -> None:
    cases = [(rot.axis_angle_to_quat, torch.zeros(3)), (rot.quat_to_axis_angle, torch.tensor([1.0, 0, 0, 0])),
             (rot.so3_log, torch.eye(3))]
    for f, x in cases:
        x = x.double().requires_grad_(True)
        f(x).sum().backward()
        assert torch.isfinite(x.grad).all()
    q = torch.tensor([1.0, 0, 0, 0], dtype=torch.float64, requires_grad=True)
    rot.quat_angle_between(q, torch.tensor([1.0, 0, 0, 0])).backward()
    assert torch.isfinite(q.grad).all()


# ----------------------------------------------------------------------------- edge cases
HALF_TURN_AXES = np.array(
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, -1, 1], [1, 1, 1], [-1, 2, -3]], dtype=float)


def test_identity() -> None:
    q = np.array([1.0, 0, 0, 0])
    np.testing.assert_array_equal(rot.quat_to_matrix(q), np.eye(3))
    np.testing.assert_array_equal(rot.matrix_to_quat(np.eye(3)), q)
    np.testing.assert_array_equal(rot.quat_to_axis_angle(q), np.zeros(3))
    np.testing.assert_array_equal(rot.axis_angle_to_quat(np.zeros(3)), q)
    np.testing.assert_array_equal(rot.rot6d_to_matrix([1.0, 0, 0, 0, 1, 0]), np.eye(3))
    for order in ALL_ORDERS:
        np.testing.assert_allclose(rot.matrix_to_euler(np.eye(3), order), 0, atol=1e-15)
    assert rot.quat_angle_between(q, q) == 0
    assert rot.matrix_angle_between(np.eye(3), np.eye(3)) == 0


def test_half_turns() -> None:
    axes = HALF_TURN_AXES / np.linalg.norm(HALF_TURN_AXES, axis=1, keepdims=True)
    rv = np.pi * axes
    R = rot.so3_exp(rv)
    np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), atol=1e-15)
    q = rot.matrix_to_quat(R)
    np.testing.assert_allclose(np.abs(q[:, 0]), 0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(rot.so3_log(R), axis=1), np.pi, atol=1e-14)
    # log at pi is only defined up to sign of the axis
    back = rot.so3_log(R)
    np.testing.assert_allclose(np.abs(np.sum(back * axes, 1)), np.pi, atol=1e-14)
    np.testing.assert_allclose(rot.quat_angle_between(q, [1.0, 0, 0, 0]), np.pi, atol=1e-15)
    np.testing.assert_allclose(rot.matrix_angle_between(R, np.eye(3)), np.pi, atol=1e-15)
    np.testing.assert_allclose(rot.matrix_angle_between(np.eye(3), R), np.pi, atol=1e-15)


@pytest.mark.parametrize("angle", [1e-15, 1e-12, 1e-9, 1e-6, 1e-4, 1.0001e-4, 1e-3])
def test_tiny_angles(angle: float) -> None:
    axis = np.array([0.48, -0.6, 0.64])
    rv = angle * axis
    q = rot.axis_angle_to_quat(rv)
    np.testing.assert_allclose(rot.quat_to_axis_angle(q), rv, rtol=1e-12, atol=0)
    np.testing.assert_allclose(rot.quat_angle_between([1.0, 0, 0, 0], q), angle, rtol=1e-12)
    R = rot.so3_exp(rv)
    np.testing.assert_allclose(rot.matrix_angle_between(np.eye(3), R), angle, rtol=1e-9)
    near_pi = rot.axis_angle_to_quat((np.pi - angle) * axis)
    np.testing.assert_allclose(rot.quat_angle_between([1.0, 0, 0, 0], near_pi), np.pi - angle, atol=1e-15)
    np.testing.assert_allclose(rot.matrix_angle_between(np.eye(3), rot.quat_to_matrix(near_pi)),
                               np.pi - angle, rtol=1e-12)


@pytest.mark.parametrize("order", ALL_ORDERS)
def test_gimbal_lock_still_reproduces_matrix(order: str) -> None:
    proper = order[0].lower() == order[2].lower()
    middles = [0.0, np.pi, 1e-9, np.pi - 1e-9] if proper else [np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9]
    for mid in middles:
        angles = np.array([0.7, mid, -0.4])
        R = rot.euler_to_matrix(angles, order)
        e = rot.matrix_to_euler(R, order)
        np.testing.assert_allclose(rot.euler_to_matrix(e, order), R, atol=1e-12)
        if mid in (0.0, np.pi, np.pi / 2, -np.pi / 2):
            last = 0 if order.isupper() else 2  # the angle applied last about the moved axis
            assert abs(e[2 - last]) < 1e-12 or abs(e[last]) < 1e-12


def test_bad_orders_raise() -> None:
    for order in ("XY", "XXY", "XyZ", "ABC", "xzz"):
        with pytest.raises(ValueError):
            rot.euler_to_matrix(np.zeros(3), order)


# ----------------------------------------------------------------------------- quaternion algebra
@given(unit_quats, unit_quats)
def test_multiply_matches_matrix_product(q1: np.ndarray, q2: np.ndarray) -> None:
    np.testing.assert_allclose(rot.quat_to_matrix(rot.quat_multiply(q1, q2)),
                               rot.quat_to_matrix(q1) @ rot.quat_to_matrix(q2), atol=1e-13)
    same_rotation(rot.quat_multiply(q1, rot.quat_conjugate(q1)), np.array([1.0, 0, 0, 0]))


def test_normalize_and_inverse() -> None:
    q = np.array([[-2.0, 0.0, -1.0, 0.0], [2.0, 0.0, 1.0, 0.0]])
    n = rot.quat_normalize(q)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1)
    assert n[0, 0] < 0
    c = rot.quat_normalize(q, positive_w=True)
    np.testing.assert_allclose(c[0], c[1])
    np.testing.assert_allclose(rot.quat_multiply(q, rot.quat_inverse(q)), [[1, 0, 0, 0]] * 2, atol=1e-15)


def test_rotate_broadcasts() -> None:
    g = rng()
    q = rot.random_quat(5, g)
    v = g.standard_normal((7, 1, 3))
    out = rot.quat_rotate(q, v)
    assert out.shape == (7, 5, 3)
    expected = np.einsum("bij,tbj->tbi", rot.quat_to_matrix(q), np.broadcast_to(v, (7, 5, 3)))
    np.testing.assert_allclose(out, expected, atol=1e-13)


def test_rot6d_orthonormalizes_noisy_input() -> None:
    d6 = rng().standard_normal((100, 6))
    R = rot.rot6d_to_matrix(d6)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1, atol=1e-14)
    first = d6[:, :3] / np.linalg.norm(d6[:, :3], axis=1, keepdims=True)
    np.testing.assert_allclose(R[:, :, 0], first, atol=1e-15)


def test_about_axis_and_skew() -> None:
    q = rot.quat_about_axis([0, 0, 2.0], np.pi / 2)
    np.testing.assert_allclose(rot.quat_rotate(q, [1.0, 0, 0]), [0, 1, 0], atol=1e-15)
    u, w = np.array([1.0, 2, 3]), np.array([-4.0, 0.5, 2])
    np.testing.assert_allclose(rot.skew(u) @ w, np.cross(u, w))
    np.testing.assert_allclose(rot.quat_about_axis(np.eye(3), np.array([0.1, 0.2, 0.3])).shape, (3, 4))


# ----------------------------------------------------------------------------- slerp and geodesic
def test_slerp_endpoints_and_constant_speed() -> None:
    g = rng()
    q0, q1 = rot.random_quat(10, g), rot.random_quat(10, g)
    np.testing.assert_allclose(rot.quat_slerp(q0, q1, 0.0), q0, atol=1e-15)
    same_rotation(rot.quat_slerp(q0, q1, 1.0), q1, tol=1e-12)
    t = np.linspace(0, 1, 11)[:, None]  # (11, 1) against (10,) batch -> (11, 10, 4)
    path = rot.quat_slerp(q0, q1, t)
    assert path.shape == (11, 10, 4)
    total = rot.quat_angle_between(q0, q1)
    assert np.all(total <= np.pi + 1e-12)  # shorter arc
    np.testing.assert_allclose(rot.quat_angle_between(q0, path), t * total, atol=1e-12)
    steps = rot.quat_angle_between(path[:-1], path[1:])
    np.testing.assert_allclose(steps, np.broadcast_to(total / 10, steps.shape), atol=1e-12)


def test_slerp_takes_shorter_arc_and_handles_equal_endpoints() -> None:
    q0 = np.array([1.0, 0, 0, 0])
    q1 = -rot.axis_angle_to_quat([0, 0, 0.2])  # same rotation as +0.2 about z, opposite sign
    mid = rot.quat_slerp(q0, q1, 0.5)
    same_rotation(mid, rot.axis_angle_to_quat([0, 0, 0.1]), tol=1e-14)
    same = rot.quat_slerp(q0, q0, np.array([0.0, 0.3, 1.0]))
    assert np.all(np.isfinite(same))
    np.testing.assert_allclose(same, np.tile(q0, (3, 1)))


@given(unit_quats, unit_quats)
def test_geodesic_symmetric_sign_invariant_and_consistent(q1: np.ndarray, q2: np.ndarray) -> None:
    a = rot.quat_angle_between(q1, q2)
    np.testing.assert_allclose(a, rot.quat_angle_between(q2, q1), atol=1e-14)
    np.testing.assert_allclose(a, rot.quat_angle_between(-q1, q2), atol=1e-14)
    R1, R2 = rot.quat_to_matrix(q1), rot.quat_to_matrix(q2)
    np.testing.assert_allclose(rot.matrix_angle_between(R1, R2), a, atol=1e-12)
    np.testing.assert_allclose(rot.matrix_angle_between(R2, R1), a, atol=1e-12)
    rel = rot.quat_multiply(rot.quat_conjugate(q1), q2)
    np.testing.assert_allclose(a, np.linalg.norm(rot.quat_to_axis_angle(rel)), atol=1e-12)
    assert 0 <= a <= np.pi


# ----------------------------------------------------------------------------- alignment
@given(arrays(np.float64, (2, 3), elements=st.floats(-10, 10)).filter(
    lambda m: np.linalg.norm(m[0]) > 1e-3 and np.linalg.norm(m[1]) > 1e-3))
# near-antiparallel: 1.25e-6 rad off (the fixed axis), 2e-6 rad off (the minimal one; 1 + a.b cancels there)
@example(np.array([[1e-5, -8.0, 0.0], [0.0, 1.0, 0.0]]))
@example(np.array([[1.6e-5, -8.0, 0.0], [0.0, 1.0, 0.0]]))
def test_between_vectors_maps_a_to_b_minimally(m: np.ndarray) -> None:
    a, b = m
    q = rot.quat_between_vectors(a, b)
    ua, ub = a / np.linalg.norm(a), b / np.linalg.norm(b)
    expected = np.arctan2(np.linalg.norm(np.cross(ua, ub)), ua @ ub)
    # within 1.4e-6 rad of antiparallel the axis is a fixed choice (docstring): b is met to that angle
    tol = 1e-9 if np.pi - expected > 1.5e-6 else 1.5e-6
    np.testing.assert_allclose(rot.quat_rotate(q, ua), ub, atol=tol)
    np.testing.assert_allclose(rot.quat_angle_between([1.0, 0, 0, 0], q), expected, atol=tol)


def test_between_vectors_parallel_and_antiparallel() -> None:
    vs = np.concatenate([np.eye(3), -np.eye(3), rng().standard_normal((20, 3))])
    for sign in (1.0, -1.0):
        q = rot.quat_between_vectors(vs, sign * 2.5 * vs)
        assert np.all(np.isfinite(q))
        np.testing.assert_allclose(rot.quat_rotate(q, vs), sign * vs, atol=1e-12)
        angle = rot.quat_angle_between([1.0, 0, 0, 0], q)
        np.testing.assert_allclose(angle, 0 if sign > 0 else np.pi, atol=1e-7)
    # an undefined direction (a zero vector) gives the identity, not NaN
    np.testing.assert_array_equal(rot.quat_between_vectors(np.zeros(3), vs[0]), [1.0, 0, 0, 0])
    gt = torch.tensor([0.0, 0, 1], dtype=torch.float64)
    assert torch.allclose(rot.quat_rotate(rot.quat_between_vectors(gt, -gt), gt), -gt)


def test_triad_recovers_rotation_and_trusts_first_pair() -> None:
    g = rng()
    R = rot.quat_to_matrix(rot.random_quat(50, g))
    a_b, b_b = g.standard_normal((50, 3)), g.standard_normal((50, 3))
    a_w, b_w = np.einsum("nij,nj->ni", R, a_b), np.einsum("nij,nj->ni", R, b_b)
    np.testing.assert_allclose(rot.triad(a_b, b_b, a_w, b_w), R, atol=1e-12)
    # a noisy second reference (any length, tilted toward a) must not tilt the first
    noisy = 3 * b_w + 0.3 * g.standard_normal((50, 3)) + 2 * a_w
    est = rot.triad(a_b, b_b, a_w, noisy)
    ua = a_w / np.linalg.norm(a_w, axis=1, keepdims=True)
    ua_est = np.einsum("nij,nj->ni", est, a_b) / np.linalg.norm(a_b, axis=1, keepdims=True)
    np.testing.assert_allclose(ua_est, ua, atol=1e-12)
    degenerate = rot.triad(a_b, a_b, a_w, a_w)
    assert np.all(np.isfinite(degenerate))
