"""The frames every driver reports, from packets built and decoded by hand.

Each packet here is packed field by field from its vendor's layout (not with our
encoders), holding an orientation whose matrix is known without any quaternion algebra:
a quarter turn about the vertical, R_WS = [[0, -1, 0], [1, 0, 0], [0, 0, 1]] (the sensor's
x axis points along world y). The driver must report the quaternion (w, x, y, z) of that
matrix, and a still sensor's specific force turned by it must read +1 g up. The drivers'
own algebra (``drivers._math``) is checked against the inference side's
(``inference.body.conventions``, itself checked against scipy).
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from drivers import _math
from drivers.bno08x import protocol as rvc
from drivers.bno08x.driver import rvc_to_sample
from drivers.movella_dot import protocol as dot
from drivers.xbus import protocol as xb
from drivers.xbus.driver import mtdata2_to_sample
from drivers.ximu3 import protocol as x3
from drivers.xsens_can import protocol as xcan
from drivers.xsens_can.driver import group_to_sample
from inference.body import conventions
from inference.body.rotations import random_quat

H = math.sqrt(0.5)
Q_TURN = (H, 0.0, 0.0, H)  # w, x, y, z: +90 deg about Z
R_TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _matrix(q) -> np.ndarray:
    """R_WS of a reported quaternion, through both algebras (they must agree)."""
    R = _math.quat_to_matrix(np.asarray(q, float))
    np.testing.assert_allclose(R, conventions.quat_to_matrix(q), atol=1e-12)
    return R


def test_xbus_quaternion_packet_by_hand():
    def item(xdi: int, fmt: str, *v: float) -> bytes:
        data = struct.pack(fmt, *v)
        return struct.pack(">HB", xdi, len(data)) + data

    data = (item(0x2010, ">4f", *Q_TURN)  # quaternion, float32, ENU
            + item(0x4020, ">3f", 0.0, 0.0, 9.81)  # acceleration
            + item(0x4030, ">3f", 0.0, 0.0, 0.0)  # free acceleration
            + item(0x8020, ">3f", 0.0, 0.0, 0.5))  # rate of turn
    body = bytes((0xFF, 0x36, len(data))) + data
    packet = b"\xfa" + body + bytes(((-sum(body)) & 0xFF,))
    s = mtdata2_to_sample(xb.decode_mtdata2(xb.decode(packet).data), "mti")
    np.testing.assert_allclose(s.quat, Q_TURN, atol=1e-7)
    np.testing.assert_allclose(_matrix(s.quat), R_TURN, atol=1e-7)
    np.testing.assert_allclose(_matrix(s.quat) @ s.acc, [0.0, 0.0, 9.81], atol=1e-5)


def test_rvc_packet_by_hand_is_yaw_then_pitch_then_roll():
    yaw, pitch, roll = 30.0, -10.0, 20.0  # degrees; the datasheet's order R = Rz(yaw) Ry(pitch) Rx(roll)
    acc_mg = (-173.6, 336.8, 925.4)
    payload = struct.pack("<B3h3h", 7, *(round(a * 100) for a in (yaw, pitch, roll)), *(round(a) for a in acc_mg))
    payload += bytes(3)
    packet = b"\xaa\xaa" + payload + bytes((sum(payload) & 0xFF,))
    s = rvc_to_sample(rvc.decode(packet), "bno")
    y, p, r = np.deg2rad([yaw, pitch, roll])
    Ry = np.array([[math.cos(p), 0.0, math.sin(p)], [0.0, 1.0, 0.0], [-math.sin(p), 0.0, math.cos(p)]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(r), -math.sin(r)], [0.0, math.sin(r), math.cos(r)]])
    R = conventions.rot_z(y) @ Ry @ Rx
    np.testing.assert_allclose(_matrix(s.quat), R, atol=1e-12)
    # free acceleration = R acc - g, in the world frame
    np.testing.assert_allclose(s.free_acc, R @ s.acc - [0.0, 0.0, _math.G], atol=1e-9)
    assert np.allclose(_math.euler_zyx_from_quat(s.quat), (y, p, r))


def test_xsens_can_quaternion_frame_by_hand():
    data = struct.pack(">4h", *(round(v * 32767) for v in Q_TURN))  # message 0x21, big-endian, 1/32767
    name, value = xcan.decode(0x21, data)
    assert name == "Quaternion"
    g = xcan.CanGroup(quat=value)
    s = group_to_sample(g, "can")
    np.testing.assert_allclose(_matrix(s.quat), R_TURN, atol=1e-4)


def test_dot_complete_quaternion_notification_by_hand():
    raw = struct.pack("<I4f3f", 1234, *Q_TURN, 0.0, 0.0, 0.0) + bytes(8)
    m = dot.decode(raw, dot.MODE_COMPLETE_QUATERNION)
    np.testing.assert_allclose(_matrix(m.quat), R_TURN, atol=1e-7)


def test_ximu3_quaternion_and_inertial_messages_by_hand():
    q = x3.decode(b"Q,1000000,0.7071068,0.0000000,0.0000000,0.7071068\r\n")  # ASCII: w, x, y, z
    i = x3.decode(b"I,1000000,0.0,0.0,0.0,0.0,0.0,1.0\r\n")  # gyro deg/s, then acc g
    quat = np.asarray(q.values) / np.linalg.norm(q.values)
    np.testing.assert_allclose(_matrix(quat), R_TURN, atol=1e-7)
    # what the driver computes for free acceleration: a still sensor reads nothing
    acc = np.asarray(i.values[3:]) * _math.G
    np.testing.assert_allclose(_math.quat_rotate(quat, acc) - [0.0, 0.0, _math.G], 0.0, atol=1e-6)


def test_the_drivers_algebra_matches_the_inference_conventions():
    rng = np.random.default_rng(7)
    a, b = random_quat(50, rng), random_quat(50, rng)
    v = rng.normal(size=(50, 3))
    Ra, Rb = conventions.quat_to_matrix(a), conventions.quat_to_matrix(b)
    np.testing.assert_allclose(_math.quat_to_matrix(a), Ra, atol=1e-12)
    np.testing.assert_allclose(_math.quat_to_matrix(_math.quat_mul(a, b)), Ra @ Rb, atol=1e-12)
    np.testing.assert_allclose(_math.quat_rotate(a, v), np.einsum("nij,nj->ni", Ra, v), atol=1e-12)
    np.testing.assert_allclose(_math.quat_rotate(_math.quat_conjugate(a), v), np.einsum("nji,nj->ni", Ra, v),
                               atol=1e-12)
    back = _math.matrix_to_quat(Ra)
    np.testing.assert_allclose(back * np.sign(back[:, :1]), a, atol=1e-12)
    rv = _math.quat_log(a)
    np.testing.assert_allclose(conventions.to_scipy(a).as_rotvec(), rv, atol=1e-12)
    np.testing.assert_allclose(_math.quat_log(-a), rv, atol=1e-12)  # q and -q: one rotation, the short way
    e = rng.uniform(-1.0, 1.0, (50, 3))
    q = _math.quat_from_euler_zyx(e[:, 0], e[:, 1], e[:, 2])
    np.testing.assert_allclose(_matrix(q), conventions.rot_z(e[:, 0]) @ conventions.quat_to_matrix(
        _math.quat_from_euler_zyx(0.0 * e[:, 0], e[:, 1], e[:, 2])), atol=1e-12)
    assert _math.quat_from_euler_zyx(0.1, 0.2, 0.3).shape == (4,)


@pytest.mark.parametrize("frame", ["nwu", "ned"])
def test_xsens_export_earth_frames_are_turns_to_z_up(frame):
    from drivers.xsens_export.frames import EARTH_TO_ENU

    R = _matrix(EARTH_TO_ENU[frame])
    up = {"nwu": [0.0, 0.0, 1.0], "ned": [0.0, 0.0, -1.0]}[frame]
    np.testing.assert_allclose(R @ up, [0.0, 0.0, 1.0], atol=1e-12)  # the frame's up (or down) -> ENU up
    north = {"nwu": [1.0, 0.0, 0.0], "ned": [1.0, 0.0, 0.0]}[frame]
    np.testing.assert_allclose(R @ north, [0.0, 1.0, 0.0], atol=1e-12)  # north is ENU's y
