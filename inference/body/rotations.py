"""Rotation conversions and operations for numpy arrays and torch tensors alike.

Conventions (DESIGN.md): quaternions are (w, x, y, z); a rotation matrix maps body to
world (R_WB), so ``R @ v_body = v_world``; 6D is the first two matrix columns
concatenated, ``(R00, R10, R20, R01, R11, R21)``; axis-angle is the rotation vector
``angle * unit_axis``; Euler orders follow scipy: upper case is intrinsic
(``"ZXY"`` -> ``R = Rz(a0) @ Rx(a1) @ Ry(a2)``, as BVH channels mean it), lower case is
extrinsic (``"zxy"`` -> ``R = Ry(a2) @ Rx(a1) @ Rz(a0)``). Both Tait-Bryan (``"XYZ"``)
and proper Euler (``"ZXZ"``) orders work. All angles are radians.

Every function takes any leading batch shape and broadcasts its inputs. It runs on
numpy or torch according to its inputs: if any input is a torch tensor, everything is
done in torch with that tensor's dtype and device (so the network side keeps autograd,
float32 and the GPU), otherwise in numpy (integers and lists become float64). Each
formula is written once against the small ``_Numpy``/``_Torch`` shims below, so the two
back ends cannot drift apart. Quantities that divide by a norm use a guarded norm and
series expansions near zero, so values and torch gradients stay finite at identity.

Composition: ``quat_multiply(a, b)`` is the rotation "b, then a" (matrix ``A @ B``), so
a body-to-world quaternion chains as ``q_WS = q_WB * q_BS``.

Numpy-only code (calibration, simulation, export, validation) uses
``inference.body.conventions`` first: yaw/heading, turns about Z and the wxyz <-> scipy
crossing, over scipy. This module is for what may meet a tensor, and for 6D and Euler.
The ``*_np`` functions near the end are some of these operations once more for one frame's
small numpy arrays (the live poser's step), where the shim's per-call cost would dominate.
"""

from __future__ import annotations

from typing import Any

import numpy as np

Array = Any  # np.ndarray or torch.Tensor; typed loosely so torch stays an optional import.

_AXES = "xyz"


# --------------------------------------------------------------------------- array shim
class _Numpy:
    """The handful of array operations the formulas need, on numpy."""

    def __init__(self, dtype: np.dtype) -> None:
        self.dtype = dtype
        self.eps = float(np.finfo(dtype).eps)

    def asarray(self, x: Any) -> np.ndarray:
        return np.asarray(x, dtype=self.dtype)

    sqrt = staticmethod(np.sqrt)
    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    atan2 = staticmethod(np.arctan2)
    abs = staticmethod(np.abs)
    where = staticmethod(np.where)

    def stack(self, xs: list[Any], axis: int = -1) -> np.ndarray:
        return np.stack(np.broadcast_arrays(*[self.asarray(x) for x in xs]), axis=axis)

    def sum(self, x: np.ndarray, axis: int = -1, keepdims: bool = False) -> np.ndarray:
        return np.sum(x, axis=axis, keepdims=keepdims)

    def cross(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.cross(a, b)

    def argmax(self, x: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.argmax(x, axis=axis)

    def take_along_axis(self, x: np.ndarray, idx: np.ndarray, axis: int) -> np.ndarray:
        return np.take_along_axis(x, idx, axis=axis)

    def mT(self, x: np.ndarray) -> np.ndarray:
        return np.swapaxes(x, -1, -2)

    def broadcast_to(self, x: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        return np.broadcast_to(x, shape)


class _Torch:
    """The same operations on torch, pinned to one dtype and device."""

    def __init__(self, torch: Any, dtype: Any, device: Any) -> None:
        self.t = torch
        self.dtype = dtype
        self.device = device
        self.eps = float(torch.finfo(dtype).eps)

    def asarray(self, x: Any) -> Any:
        return self.t.as_tensor(x, dtype=self.dtype, device=self.device)

    def sqrt(self, x: Any) -> Any:
        return self.t.sqrt(x)

    def sin(self, x: Any) -> Any:
        return self.t.sin(x)

    def cos(self, x: Any) -> Any:
        return self.t.cos(x)

    def atan2(self, y: Any, x: Any) -> Any:
        return self.t.atan2(y, x)

    def abs(self, x: Any) -> Any:
        return self.t.abs(x)

    def where(self, c: Any, a: Any, b: Any) -> Any:
        return self.t.where(c, self.asarray(a), self.asarray(b))

    def stack(self, xs: list[Any], axis: int = -1) -> Any:
        return self.t.stack(self.t.broadcast_tensors(*[self.asarray(x) for x in xs]), dim=axis)

    def sum(self, x: Any, axis: int = -1, keepdims: bool = False) -> Any:
        return self.t.sum(x, dim=axis, keepdim=keepdims)

    def cross(self, a: Any, b: Any) -> Any:
        return self.t.linalg.cross(*self.t.broadcast_tensors(a, b), dim=-1)

    def argmax(self, x: Any, axis: int = -1) -> Any:
        return self.t.argmax(x, dim=axis)

    def take_along_axis(self, x: Any, idx: Any, axis: int) -> Any:
        return self.t.take_along_dim(x, idx, dim=axis)

    def mT(self, x: Any) -> Any:
        return x.transpose(-1, -2)

    def broadcast_to(self, x: Any, shape: tuple[int, ...]) -> Any:
        return self.t.broadcast_to(x, shape)


def _is_torch(x: Any) -> bool:
    return type(x).__module__.split(".")[0] == "torch"


def _ns(*xs: Any) -> tuple[Any, ...]:
    """Pick the back end from the inputs and convert them all to it.

    Returns ``(xp, *converted)``. Torch is imported only when a tensor is passed, so
    numpy-only users (drivers, exporters) do not pay for it.
    """
    tensors = [x for x in xs if _is_torch(x)]
    if tensors:
        import torch

        floats = [x.dtype for x in tensors if x.is_floating_point()]
        dtype = floats[0] if floats else torch.float64
        for d in floats[1:]:
            dtype = torch.promote_types(dtype, d)
        xp: Any = _Torch(torch, dtype, tensors[0].device)
    else:
        # Only real float arrays decide the dtype, so a Python scalar such as a slerp t
        # does not silently widen float32 data; everything else becomes float64.
        floats = [x.dtype for x in xs if isinstance(x, np.ndarray) and np.issubdtype(x.dtype, np.floating)]
        xp = _Numpy(np.result_type(*floats) if floats else np.dtype(np.float64))
    return (xp, *[xp.asarray(x) for x in xs])


def _dot(xp: Any, a: Array, b: Array, keepdims: bool = False) -> Array:
    return xp.sum(a * b, axis=-1, keepdims=keepdims)


def _norm(xp: Any, v: Array, keepdims: bool = False) -> Array:
    """Euclidean norm whose torch gradient is 0 rather than NaN at the zero vector."""
    s = _dot(xp, v, v, keepdims)
    pos = s > 0
    return xp.where(pos, xp.sqrt(xp.where(pos, s, 1.0)), 0.0)


def _normalize_vec(xp: Any, v: Array) -> Array:
    return v / _norm(xp, v, keepdims=True)


def _any_perpendicular(xp: Any, a: Array) -> Array:
    """A unit vector perpendicular to ``a``, continuous wherever a choice is free.

    Of ``a x ex`` and ``a x ey`` the longer has squared norm >= |a|^2 / 2, so it never
    degenerates for non-zero ``a``.
    """
    zero = a[..., 0] * 0
    p1 = xp.stack([zero, a[..., 2], -a[..., 1]])  # a x ex
    p2 = xp.stack([-a[..., 2], zero, a[..., 0]])  # a x ey
    use1 = _dot(xp, p1, p1, True) >= _dot(xp, p2, p2, True)
    return _normalize_vec(xp, xp.where(use1, p1, p2))


# --------------------------------------------------------------------------- quaternions
def quat_identity(shape: tuple[int, ...] = (), like: Array | None = None) -> Array:
    """Identity quaternions of a batch shape, on ``like``'s back end/dtype/device if given."""
    xp, ref = _ns(np.zeros(0) if like is None else like)
    one = xp.asarray(np.ones(shape))
    zero = one * 0
    return xp.stack([one, zero, zero, zero])


def quat_normalize(q: Array, positive_w: bool = False) -> Array:
    """Scale to unit length; ``positive_w`` picks the w >= 0 one of the pair q, -q.

    Canonical sign matters wherever quaternions are compared or averaged element-wise,
    because q and -q are the same rotation.
    """
    xp, q = _ns(q)
    q = q / _norm(xp, q, keepdims=True)
    if positive_w:
        q = xp.where(q[..., :1] < 0, -q, q)
    return q


def quat_conjugate(q: Array) -> Array:
    """The inverse rotation of a unit quaternion, without a division."""
    xp, q = _ns(q)
    return q * xp.asarray([1.0, -1.0, -1.0, -1.0])


def quat_inverse(q: Array) -> Array:
    """Exact inverse also for non-unit quaternions (conjugate over squared norm)."""
    xp, q = _ns(q)
    return quat_conjugate(q) / _dot(xp, q, q, keepdims=True)


def quat_multiply(a: Array, b: Array) -> Array:
    """Hamilton product ``a * b``: rotation ``b`` applied first, then ``a`` (like ``A @ B``)."""
    xp, a, b = _ns(a, b)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return xp.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def quat_rotate(q: Array, v: Array) -> Array:
    """Rotate 3-vectors by unit quaternions (``R(q) @ v``) without building matrices."""
    xp, q, v = _ns(q, v)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * xp.cross(u, v)
    return v + w * t + xp.cross(u, t)


def quat_to_matrix(q: Array) -> Array:
    """Body-to-world matrix; tolerates non-unit q by dividing by |q|^2 (one formula, no sqrt)."""
    xp, q = _ns(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / _dot(xp, q, q)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    rows = [
        xp.stack([1.0 - yy - zz, xy - wz, xz + wy]),
        xp.stack([xy + wz, 1.0 - xx - zz, yz - wx]),
        xp.stack([xz - wy, yz + wx, 1.0 - xx - yy]),
    ]
    return xp.stack(rows, axis=-2)


def matrix_to_quat(R: Array) -> Array:
    """Quaternion with w >= 0 from a rotation matrix, accurate for every angle.

    Of the four algebraically equivalent formulas (each divides by one quaternion
    component) we take, per element, the one whose divisor is largest, so there is no
    cancellation near 180 degrees where the trace-only formula fails.
    """
    xp, R = _ns(R)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = [[R[..., i, j] for j in range(3)] for i in range(3)]
    cands = xp.stack([
        xp.stack([1.0 + r00 + r11 + r22, r21 - r12, r02 - r20, r10 - r01]),
        xp.stack([r21 - r12, 1.0 + r00 - r11 - r22, r01 + r10, r02 + r20]),
        xp.stack([r02 - r20, r01 + r10, 1.0 - r00 + r11 - r22, r12 + r21]),
        xp.stack([r10 - r01, r02 + r20, r12 + r21, 1.0 - r00 - r11 + r22]),
    ], axis=-2)  # (..., 4 candidates, 4 components); candidate m equals 4 q_m q
    diag = xp.stack([cands[..., m, m] for m in range(4)])
    idx = xp.argmax(diag, axis=-1)[..., None, None]
    best = xp.take_along_axis(cands, idx, axis=-2)[..., 0, :]
    return quat_normalize(best, positive_w=True)


# --------------------------------------------------------------------------- 6D
def matrix_to_rot6d(R: Array) -> Array:
    """First two columns concatenated: the continuous representation the network uses."""
    xp, R = _ns(R)
    return xp.stack([R[..., 0, 0], R[..., 1, 0], R[..., 2, 0], R[..., 0, 1], R[..., 1, 1], R[..., 2, 1]])


def rot6d_to_matrix(d6: Array) -> Array:
    """Nearest-ish rotation to a raw network 6D output by Gram-Schmidt.

    The first column keeps its direction exactly, which is what makes the map smooth and
    surjective (and so a good regression target); the third column completes a
    right-handed frame.
    """
    xp, d6 = _ns(d6)
    b1 = _normalize_vec(xp, d6[..., 0:3])
    a2 = d6[..., 3:6]
    b2 = _normalize_vec(xp, a2 - _dot(xp, b1, a2, keepdims=True) * b1)
    b3 = xp.cross(b1, b2)
    return xp.stack([b1, b2, b3], axis=-1)


# --------------------------------------------------------------------------- axis-angle / exp / log
def axis_angle_to_quat(rotvec: Array) -> Array:
    """Quaternion of a rotation vector; a series near zero keeps it exact and differentiable."""
    xp, rotvec = _ns(rotvec)
    th = _norm(xp, rotvec)
    small = th < 1e-4
    th_safe = xp.where(small, 1.0, th)
    k = xp.where(small, 0.5 - th * th / 48.0, xp.sin(0.5 * th_safe) / th_safe)
    return xp.stack([xp.cos(0.5 * th), k * rotvec[..., 0], k * rotvec[..., 1], k * rotvec[..., 2]])


def quat_to_axis_angle(q: Array) -> Array:
    """Rotation vector with angle in [0, pi]; the shorter of the q / -q readings.

    ``atan2`` instead of ``acos`` keeps precision near 0 and pi. Scale-invariant, so a
    slightly non-unit q is fine.
    """
    xp, q = _ns(q)
    q = xp.where(q[..., :1] < 0, -q, q)
    w, v = q[..., 0], q[..., 1:]
    n = _norm(xp, v)
    small = n < 1e-4 * w
    n_safe = xp.where(small, 1.0, n)
    w_safe = xp.where(small, w, 1.0)
    r2 = (n / w_safe) ** 2
    scale = xp.where(small, 2.0 / w_safe * (1.0 - r2 / 3.0), 2.0 * xp.atan2(n, w) / n_safe)
    return scale[..., None] * v


def quat_continuous(q: np.ndarray) -> np.ndarray:
    """A sequence of quaternions (T, ..., 4) with each on the hemisphere of its predecessor
    (a copy): interpolating between neighbours then never crosses the double cover."""
    q = np.array(q, dtype=np.float64)
    if len(q) > 1:
        d = np.sum(q[1:] * q[:-1], axis=-1, keepdims=True)
        q[1:] *= np.cumprod(np.where(d < 0, -1.0, 1.0), axis=0)
    return q


def quat_exp(rotvec: Array) -> Array:
    """Exponential map from the tangent space (rotation vector) to unit quaternions.

    The tangent is the rotation vector, i.e. twice the pure-quaternion logarithm, so
    ``quat_exp`` and ``quat_log`` pair with angular velocity * dt directly.
    """
    return axis_angle_to_quat(rotvec)


def quat_log(q: Array) -> Array:
    """Logarithm map to a rotation vector (angle <= pi); inverse of ``quat_exp``."""
    return quat_to_axis_angle(q)


def skew(v: Array) -> Array:
    """Cross-product matrix ``[v]_x`` with ``[v]_x @ u == v x u``."""
    xp, v = _ns(v)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = x * 0
    return xp.stack([xp.stack([zero, -z, y]), xp.stack([z, zero, -x]), xp.stack([-y, x, zero])], axis=-2)


def so3_exp(rotvec: Array) -> Array:
    """Rotation matrix of a rotation vector (Rodrigues), exact for tiny angles."""
    return quat_to_matrix(axis_angle_to_quat(rotvec))


def so3_log(R: Array) -> Array:
    """Rotation vector of a rotation matrix; goes through the quaternion to stay exact at pi."""
    return quat_to_axis_angle(matrix_to_quat(R))


def axis_angle_to_matrix(rotvec: Array) -> Array:
    """Same as ``so3_exp``; named for symmetry with the other conversions."""
    return so3_exp(rotvec)


def matrix_to_axis_angle(R: Array) -> Array:
    """Same as ``so3_log``; named for symmetry with the other conversions."""
    return so3_log(R)


def quat_about_axis(axis: Array, angle: Array) -> Array:
    """Rotation by ``angle`` (right-hand rule) about ``axis``, which need not be unit length."""
    xp, axis, angle = _ns(axis, angle)
    u = _normalize_vec(xp, axis)
    half = 0.5 * angle
    s = xp.sin(half)
    return xp.stack([xp.cos(half), s * u[..., 0], s * u[..., 1], s * u[..., 2]])


def matrix_about_axis(axis: Array, angle: Array) -> Array:
    """Matrix form of ``quat_about_axis``."""
    return quat_to_matrix(quat_about_axis(axis, angle))


# --------------------------------------------------------------------------- Euler angles
def _parse_order(order: str) -> tuple[list[int], bool]:
    """Axis indices in intrinsic application order, and whether the input was extrinsic.

    Extrinsic "abc" with angles (t0, t1, t2) is intrinsic "CBA" with (t2, t1, t0), so
    only the intrinsic case needs formulas.
    """
    if len(order) != 3 or not (order.isupper() or order.islower()) or set(order.lower()) - set(_AXES):
        raise ValueError(f"Euler order must be 3 letters of xyz, all upper (intrinsic) or lower: {order!r}")
    idx = [_AXES.index(c) for c in order.lower()]
    if idx[0] == idx[1] or idx[1] == idx[2]:
        raise ValueError(f"consecutive Euler axes must differ: {order!r}")
    extrinsic = order.islower()
    return (idx[::-1] if extrinsic else idx), extrinsic


def euler_to_quat(angles: Array, order: str) -> Array:
    """Quaternion of Euler angles (..., 3) in radians; see the module doc for the order rule."""
    axes, extrinsic = _parse_order(order)
    xp, angles = _ns(angles)
    if extrinsic:
        angles = xp.stack([angles[..., 2], angles[..., 1], angles[..., 0]])
    q = None
    for n, ax in enumerate(axes):
        half = 0.5 * angles[..., n]
        zero = half * 0
        comps = [xp.cos(half), zero, zero, zero]
        comps[1 + ax] = xp.sin(half)
        qa = xp.stack(comps)
        q = qa if q is None else quat_multiply(q, qa)
    return q


def euler_to_matrix(angles: Array, order: str) -> Array:
    """Matrix of Euler angles; intrinsic "ZXY" gives ``Rz(a0) @ Rx(a1) @ Ry(a2)``."""
    return quat_to_matrix(euler_to_quat(angles, order))


def matrix_to_euler(R: Array, order: str) -> Array:
    """Euler angles (..., 3) of a rotation matrix, in scipy's ranges.

    First and last angles lie in (-pi, pi]; the middle one in [-pi/2, pi/2] for
    Tait-Bryan orders, [0, pi] for proper Euler orders. The first angle is read from the
    matrix, the last one from what remains after undoing the first two, so the angles
    always reproduce R even arbitrarily close to gimbal lock; exactly at gimbal lock the
    angle of the last intrinsic rotation is 0 (for extrinsic orders: the first returned
    angle) and the free combination goes into the other outer angle.
    """
    axes, extrinsic = _parse_order(order)
    xp, R = _ns(R)
    i, j = axes[0], axes[1]
    proper = axes[2] == i
    l = 3 - i - j
    eps = 1.0 if (j - i) % 3 == 1 else -1.0  # parity of (i, j, l)
    Rij = lambda a, b: R[..., a, b]  # noqa: E731
    tol = 100.0 * xp.eps
    if proper:
        sb = xp.sqrt(Rij(i, j) ** 2 + Rij(i, l) ** 2)
        b = xp.atan2(sb, Rij(i, i))
        a_gen = xp.atan2(Rij(j, i), -eps * Rij(l, i))
    else:
        sb = xp.sqrt(Rij(i, i) ** 2 + Rij(i, j) ** 2)
        b = xp.atan2(eps * Rij(i, l), sb)
        a_gen = xp.atan2(-eps * Rij(j, l), Rij(l, l))
    a_lock = xp.atan2(eps * Rij(l, j), Rij(j, j))
    a = xp.where(sb < tol, a_lock, a_gen)
    ca, sa = xp.cos(a), xp.sin(a)
    # Row j of R_i(a)^T R; it equals row j of R_j(b) R_k(c), which only depends on c.
    n_j = lambda m: ca * Rij(j, m) + eps * sa * Rij(l, m)  # noqa: E731
    if proper:
        c = xp.atan2(-eps * n_j(l), n_j(j))
    else:
        c = xp.atan2(eps * n_j(i), n_j(j))
    out = [c, b, a] if extrinsic else [a, b, c]
    return xp.stack(out)


def quat_to_euler(q: Array, order: str) -> Array:
    """Euler angles of a quaternion (via the matrix, which handles every order uniformly)."""
    return matrix_to_euler(quat_to_matrix(q), order)


# --------------------------------------------------------------------------- remaining pairs
def quat_to_rot6d(q: Array) -> Array:
    """6D of a quaternion."""
    return matrix_to_rot6d(quat_to_matrix(q))


def rot6d_to_quat(d6: Array) -> Array:
    """Quaternion (w >= 0) of a raw 6D, orthonormalised first."""
    return matrix_to_quat(rot6d_to_matrix(d6))


def axis_angle_to_rot6d(rotvec: Array) -> Array:
    """6D of a rotation vector."""
    return matrix_to_rot6d(so3_exp(rotvec))


def rot6d_to_axis_angle(d6: Array) -> Array:
    """Rotation vector of a raw 6D."""
    return so3_log(rot6d_to_matrix(d6))


def euler_to_rot6d(angles: Array, order: str) -> Array:
    """6D of Euler angles."""
    return matrix_to_rot6d(euler_to_matrix(angles, order))


def rot6d_to_euler(d6: Array, order: str) -> Array:
    """Euler angles of a raw 6D."""
    return matrix_to_euler(rot6d_to_matrix(d6), order)


def euler_to_axis_angle(angles: Array, order: str) -> Array:
    """Rotation vector of Euler angles."""
    return quat_to_axis_angle(euler_to_quat(angles, order))


def axis_angle_to_euler(rotvec: Array, order: str) -> Array:
    """Euler angles of a rotation vector."""
    return quat_to_euler(axis_angle_to_quat(rotvec), order)


# --------------------------------------------------------------------------- metrics, interpolation
def quat_angle_between(q1: Array, q2: Array) -> Array:
    """Geodesic angle in [0, pi] between rotations, insensitive to quaternion sign.

    ``2 atan2(|v|, |w|)`` of the relative quaternion stays accurate at 0 and pi, where
    ``acos`` of a dot product loses half the digits.
    """
    xp, q1, q2 = _ns(q1, q2)
    d = quat_multiply(quat_conjugate(q1), q2)
    return 2.0 * xp.atan2(_norm(xp, d[..., 1:]), xp.abs(d[..., 0]))


def matrix_angle_between(R1: Array, R2: Array) -> Array:
    """Geodesic angle in [0, pi] between rotation matrices.

    Uses both sin (from the skew part) and cos (from the trace) of the relative rotation
    in ``atan2``, so it is accurate at 0 and at pi, unlike ``acos((tr - 1) / 2)``.
    """
    xp, R1, R2 = _ns(R1, R2)
    M = xp.mT(R1) @ R2
    s = xp.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]])
    tr = M[..., 0, 0] + M[..., 1, 1] + M[..., 2, 2]
    return xp.atan2(_norm(xp, s), tr - 1.0)


def quat_slerp(q0: Array, q1: Array, t: Array) -> Array:
    """Constant-angular-speed interpolation along the shorter arc, ``q0 * exp(t log(q0^-1 q1))``.

    ``t`` broadcasts against the quaternions' batch shape, e.g. ``q0, q1: (4,)`` and
    ``t: (T,)`` give ``(T, 4)``. Built on the guarded exp/log, so nearly equal endpoints
    need no special case. At t = 1 the result equals q1 up to sign.
    """
    xp, q0, q1, t = _ns(q0, q1, t)
    rel = quat_multiply(quat_conjugate(q0), q1)
    return quat_multiply(q0, quat_exp(t[..., None] * quat_log(rel)))


# --------------------------------------------------------------------------- alignment
def quat_between_vectors(a: Array, b: Array) -> Array:
    """Smallest rotation q with ``quat_rotate(q, a)`` parallel to ``b`` (lengths ignored).

    Built as the normalised ``(1 + a.b, a x b)`` of the unit vectors, the half-way
    quaternion, which needs no trig. ``1 + a.b`` is taken as ``|a + b|^2 / 2`` and
    ``a x b`` as ``a x (a + b)``, which keep their precision as the vectors near
    antiparallel, where the plain forms cancel. Within ~1.4e-6 rad of antiparallel the
    minimal axis is set by the inputs' rounding, so we turn 180 degrees about a
    deterministic axis perpendicular to ``a`` instead (b is then met to within that
    angle): the retargeter relies on it for rigs whose bones are antiparallel to ~1e-7.
    A zero vector gives the identity. Note the direction: this maps a to b (scipy's
    ``align_vectors(a, b)`` maps b to a).
    """
    xp, a, b = _ns(a, b)
    na, nb = _norm(xp, a, True), _norm(xp, b, True)
    ua, ub = a / xp.where(na > 0, na, 1.0), b / xp.where(nb > 0, nb, 1.0)  # a zero vector: identity
    half = ua + ub
    w = 0.5 * _dot(xp, half, half, True)
    v = xp.cross(ua, half)
    anti = w <= 1e-12  # |a + b| < 1.4e-6
    zero = w * 0
    perp = xp.broadcast_to(_any_perpendicular(xp, xp.where(na > 0, a, 1.0)), v.shape)  # no 0/0 warning
    q = xp.where(anti, xp.stack([zero[..., 0], perp[..., 0], perp[..., 1], perp[..., 2]]),
                 xp.stack([w[..., 0], v[..., 0], v[..., 1], v[..., 2]]))
    return quat_normalize(q)


def triad(a_body: Array, b_body: Array, a_world: Array, b_world: Array) -> Array:
    """Body-to-world matrix from two vector pairs (TRIAD), e.g. gravity and a heading.

    ``a`` is trusted: ``R @ a_body`` is exactly parallel to ``a_world``; ``b`` only fixes
    the rotation about ``a`` (its component along ``a`` is ignored), which is the right
    split when one reference (gravity) is much better than the other (magnetic north, a
    walking direction). Parallel a and b leave that rotation undefined; we then fall back
    to an arbitrary but finite frame.
    """
    xp, a_body, b_body, a_world, b_world = _ns(a_body, b_body, a_world, b_world)

    def frame(a: Array, b: Array) -> Array:
        t1 = _normalize_vec(xp, a)
        c = xp.cross(t1, b)
        degenerate = _norm(xp, c, True) <= 1e-12 * _norm(xp, b, True)
        t2 = _normalize_vec(xp, xp.where(degenerate, _any_perpendicular(xp, t1), c))
        return xp.stack([t1, t2, xp.cross(t1, t2)], axis=-1)

    return frame(a_world, b_world) @ xp.mT(frame(a_body, b_body))


# --------------------------------------------------------------------------- facing
def facing_x(h: Array) -> Array:
    """(..., 3, 3) R_z(-heading of h): the turn about world Z that makes ground-plane
    directions h (..., 2) face +X. The heading frames of the learned helpers (contact
    detector, pelvis odometry) are built with it, on tensors in training; numpy code without
    a tensor in sight uses ``conventions`` (``rot_z``, ``turn_cs``)."""
    xp, h = _ns(h)
    yaw = xp.atan2(h[..., 1], h[..., 0])
    up = xp.broadcast_to(xp.asarray([0.0, 0.0, 1.0]), (*yaw.shape, 3))
    return matrix_about_axis(up, -yaw)


# --------------------------------------------------------------------------- one frame on numpy
# The live poser's per-frame path (``inference/poser``) turns one frame's 24 segments at a
# time. Through the back-end shim above, each call's conversions and stacking cost more
# than its arithmetic (a frame made ~170 tensor conversions before these kernels), so the
# same operations are here once more, for numpy arrays only, keeping the input's float
# dtype (float32 in, float32 out, as the model's side computes), with the index work done
# at import. Same conventions, same guards; tests/inference/body/test_frame_kernels.py
# holds each to its general counterpart above, tiny and near-pi angles included.

_C1 = np.array([1, 2, 0])
_C2 = np.array([2, 0, 1])


def _cross_np(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis, cheaper than ``np.cross`` on a few vectors."""
    return a.take(_C1, -1) * b.take(_C2, -1) - a.take(_C2, -1) * b.take(_C1, -1)


def _norm_np(v: np.ndarray) -> np.ndarray:
    return np.sqrt((v * v).sum(-1, keepdims=True))


def rot6d_columns_np(d6: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first two columns of ``rot6d_to_matrix_np``, for callers that need no more (the
    6D of a turned rotation is its turned columns)."""
    a1, a2 = d6[..., 0:3], d6[..., 3:6]
    b1 = a1 / _norm_np(a1)
    b2 = a2 - (b1 * a2).sum(-1, keepdims=True) * b1
    return b1, b2 / _norm_np(b2)


def rot6d_to_matrix_np(d6: np.ndarray) -> np.ndarray:
    """``rot6d_to_matrix`` of numpy (..., 6)."""
    b1, b2 = rot6d_columns_np(d6)
    out = np.empty((*d6.shape[:-1], 3, 3), dtype=b1.dtype)
    out[..., 0] = b1
    out[..., 1] = b2
    out[..., 2] = _cross_np(b1, b2)
    return out


def matrix_to_rot6d_np(R: np.ndarray) -> np.ndarray:
    """``matrix_to_rot6d`` of numpy (..., 3, 3)."""
    return np.swapaxes(R[..., :, :2], -1, -2).reshape(*R.shape[:-2], 6)


def _candidate_map() -> tuple[np.ndarray, np.ndarray]:
    """``matrix_to_quat``'s four candidates (4 q_m q for m = w, x, y, z) as one linear map of
    the nine matrix entries (row-major) plus a constant: ``cands = r9 @ W + B``, so a frame's
    candidates are one matrix product instead of sixteen stacked sums."""
    W, B = np.zeros((9, 4, 4)), np.zeros((4, 4))
    terms = [  # (entry index, sign) per candidate m and component c, as in matrix_to_quat
        [((0, 1), (4, 1), (8, 1)), ((7, 1), (5, -1)), ((2, 1), (6, -1)), ((3, 1), (1, -1))],
        [((7, 1), (5, -1)), ((0, 1), (4, -1), (8, -1)), ((1, 1), (3, 1)), ((2, 1), (6, 1))],
        [((2, 1), (6, -1)), ((1, 1), (3, 1)), ((0, -1), (4, 1), (8, -1)), ((5, 1), (7, 1))],
        [((3, 1), (1, -1)), ((2, 1), (6, 1)), ((5, 1), (7, 1)), ((0, -1), (4, -1), (8, 1))],
    ]
    for m, row in enumerate(terms):
        for c, entries in enumerate(row):
            for i, sign in entries:
                W[i, m, c] = sign
        B[m, m] = 1.0
    return W.reshape(9, 16), B.reshape(16)


_QW, _QB = _candidate_map()
_QW32, _QB32 = _QW.astype(np.float32), _QB.astype(np.float32)
_DIAG = np.arange(4)


def matrix_to_quat_np(R: np.ndarray) -> np.ndarray:
    """``matrix_to_quat`` (largest divisor, w >= 0) of numpy (n, 3, 3)."""
    n = R.shape[0]
    W, B = (_QW32, _QB32) if R.dtype == np.float32 else (_QW, _QB)
    cands = (R.reshape(n, 9) @ W + B).reshape(n, 4, 4)
    best = cands[np.arange(n), np.argmax(cands[:, _DIAG, _DIAG], axis=-1)]
    q = best / _norm_np(best)
    return np.where(q[:, :1] < 0, -q, q)


def quat_to_axis_angle_np(q: np.ndarray) -> np.ndarray:
    """``quat_to_axis_angle`` (angle in [0, pi], the series near zero) of numpy (..., 4)."""
    q = np.where(q[..., :1] < 0, -q, q)
    w, v = q[..., 0], q[..., 1:]
    n = _norm_np(v)[..., 0]
    small = n < 1e-4 * w  # else n > 0: w >= 0, and q is not zero
    w_safe = np.where(small, w, 1.0)
    r2 = (n / w_safe) ** 2
    scale = np.where(small, 2.0 / w_safe * (1.0 - r2 / 3.0), 2.0 * np.arctan2(n, w) / np.where(small, 1.0, n))
    return scale[..., None] * v


def so3_log_np(R: np.ndarray) -> np.ndarray:
    """``so3_log`` of numpy (n, 3, 3)."""
    return quat_to_axis_angle_np(matrix_to_quat_np(R))


# the skew-symmetric [v]_x as a linear map of v: flat (9,) entries = v @ _SKEW
_SKEW = np.zeros((3, 9))
for _k, (_i, _j) in enumerate([(2, 1), (0, 2), (1, 0)]):
    _SKEW[_k, 3 * _i + _j], _SKEW[_k, 3 * _j + _i] = 1.0, -1.0
_SKEW32 = _SKEW.astype(np.float32)
_EYE = np.eye(3)
_EYE32 = _EYE.astype(np.float32)


def quat_to_matrix_np(q: np.ndarray) -> np.ndarray:
    """``quat_to_matrix`` of numpy (..., 4), non-unit q tolerated: with s = 2 / |q|^2,
    R = s v v^T + (1 - s |v|^2) I + s w [v]_x (the same entries, ``1 - yy - zz`` =
    ``1 - (xx + yy + zz) + xx``, summed in another order)."""
    f32 = q.dtype == np.float32
    w, v = q[..., :1], q[..., 1:]
    s = 2.0 / (q * q).sum(-1, keepdims=True)
    sv = s * v
    out = sv[..., :, None] * v[..., None, :]  # s v v^T
    out += (1.0 - (sv * v).sum(-1))[..., None, None] * (_EYE32 if f32 else _EYE)
    out += ((sv * w) @ (_SKEW32 if f32 else _SKEW)).reshape(out.shape)
    return out


def quat_power_np(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """q^t of numpy unit quaternions (..., 4) with w >= 0: the same axis, ``t`` (...) times the
    angle; ``exp(t log q)`` with the axis never formed (identity where q is)."""
    v = q[..., 1:]
    n = np.sqrt((v * v).sum(-1))
    th = t * np.arctan2(n, q[..., 0])
    out = np.empty_like(q)
    out[..., 0] = np.cos(th)
    out[..., 1:] = (np.sin(th) / np.where(n > 0, n, 1.0))[..., None] * v
    return out


def matrix_about_axis_np(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``matrix_about_axis`` of numpy: (..., 3, 3) turns by ``angle`` (...) about one unit ``axis`` (3,)."""
    half = 0.5 * angle
    q = np.empty((*np.shape(angle), 4), dtype=np.result_type(angle, axis))
    q[..., 0] = np.cos(half)
    q[..., 1:] = np.sin(half)[..., None] * axis
    return quat_to_matrix_np(q)


# --------------------------------------------------------------------------- helpers for tests and synthesis
def random_quat(shape: tuple[int, ...] | int = (), rng: np.random.Generator | None = None) -> np.ndarray:
    """Uniformly distributed unit quaternions (w >= 0), float64 numpy.

    Normalised 4D Gaussians are uniform on SO(3); synthesis and tests both need that, not
    uniform Euler angles, which crowd near the poles.
    """
    rng = np.random.default_rng() if rng is None else rng
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    return quat_normalize(rng.standard_normal((*shape, 4)), positive_w=True)


__all__ = [
    "quat_continuous",
    "axis_angle_to_euler", "axis_angle_to_matrix", "axis_angle_to_quat", "axis_angle_to_rot6d",
    "euler_to_axis_angle", "euler_to_matrix", "euler_to_quat", "euler_to_rot6d",
    "matrix_about_axis", "matrix_angle_between", "matrix_to_axis_angle", "matrix_to_euler",
    "matrix_to_quat", "matrix_to_rot6d", "quat_about_axis", "quat_angle_between", "quat_between_vectors",
    "quat_conjugate", "quat_exp", "quat_identity", "quat_inverse", "quat_log", "quat_multiply",
    "quat_normalize", "quat_rotate", "quat_slerp", "quat_to_axis_angle", "quat_to_euler",
    "quat_to_matrix", "quat_to_rot6d", "random_quat", "rot6d_to_axis_angle", "rot6d_to_euler",
    "rot6d_to_matrix", "rot6d_to_quat", "skew", "so3_exp", "so3_log", "triad",
    "facing_x", "matrix_about_axis_np", "matrix_to_quat_np", "matrix_to_rot6d_np", "quat_to_axis_angle_np",
    "quat_power_np", "quat_to_matrix_np", "rot6d_columns_np", "rot6d_to_matrix_np", "so3_log_np",
]
