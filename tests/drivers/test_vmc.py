"""VMC protocol device messages: the wire format both ways, Unity's frame to ours on poses
worked out by hand, malformed datagrams, and the ``vmc-in://`` device on a real UDP socket."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from app.capture.twins import free_udp_port
from app.streams.unity import rot_to_unity, unity_quat, vec_to_unity
from drivers import make_device, open_device
from drivers.vmc import protocol as vmc
from drivers.vmc.device import VmcInDevice
from inference.body.rotations import quat_to_matrix, random_quat


def unity_message(address: str, serial: object, *values: object) -> bytes:
    """A device message built by hand in Unity's frame (not through our encode)."""
    b = OscMessageBuilder(address=address)
    b.add_arg(serial)
    for v in values:
        b.add_arg(v)
    return b.build().dgram


def decode_one(address: str, p_unity, q_unity_xyzw) -> vmc.TrackedSample:
    (s,) = vmc.decode(unity_message(address, "LHR-1", *map(float, p_unity), *map(float, q_unity_xyzw)))
    return s


def R(s: vmc.TrackedSample) -> np.ndarray:
    return quat_to_matrix(s.quat)


# --- the wire format --------------------------------------------------------------------------------------
def test_encode_decode_round_trip_of_frames():
    rng = np.random.default_rng(3)
    for _ in range(50):
        poses = [vmc.DevicePose(kind, f"S-{kind}-{k}", rng.normal(0, 1.5, 3), random_quat(rng=rng))
                 for k, kind in enumerate(("hmd", "con", "con", "tra"))]
        t = float(rng.uniform(0, 1000))
        for local in (False, True):
            got = vmc.decode(vmc.encode_frame(poses, t, local=local))
            assert [(g.serial, g.kind, g.local) for g in got] == [(p.serial, p.kind, local) for p in poses]
            for g, p in zip(got, poses, strict=True):
                assert g.sender_time == pytest.approx(t, rel=1e-6)  # a float32 on the wire
                np.testing.assert_allclose(g.position, p.position, atol=1e-5)
                assert abs(float(np.dot(g.quat, p.quat))) == pytest.approx(1.0, abs=1e-6)
    single = vmc.decode(vmc.encode("con", "C-7", [0.2, 0.3, 1.1], [1.0, 0.0, 0.0, 0.0]))
    assert [(s.serial, s.kind, s.local, s.sender_time) for s in single] == [("C-7", "con", False, None)]


def test_conversion_is_a_proper_rotation_and_its_inverse():
    rng = np.random.default_rng(5)
    u = rng.normal(size=(200, 3))
    qu = random_quat((200,), rng=rng)[:, [1, 2, 3, 0]]  # Unity order x y z w
    p, q = vmc.unity_to_world(u, qu)
    u2, qu2 = vmc.world_to_unity(p, q)
    np.testing.assert_allclose(u2, u, atol=1e-12)
    np.testing.assert_allclose(qu2, qu, atol=1e-12)
    # what "the same rotation in another frame" means: rotating a vector in Unity and carrying the
    # result across equals carrying the vector across and rotating it in ours
    A = vmc.UNITY_TO_WORLD
    RU = quat_to_matrix(qu[:, [3, 0, 1, 2]])  # Unity's quaternion algebra is ours in (w, x, y, z)
    Rw = quat_to_matrix(q)
    v = rng.normal(size=(200, 3))
    np.testing.assert_allclose((Rw @ (v @ A.T)[..., None])[..., 0], ((RU @ v[..., None])[..., 0]) @ A.T, atol=1e-12)
    assert np.allclose(np.linalg.det(Rw), 1.0)
    assert np.linalg.det(A) == pytest.approx(-1.0)  # the handedness flip lives in the axis map only
    # and it is the inverse of the map app/streams/unity.py sends with
    np.testing.assert_allclose(vec_to_unity(p), u, atol=1e-12)
    uq = unity_quat(rot_to_unity(Rw))
    np.testing.assert_allclose(np.abs(np.sum(uq * qu, axis=-1)), 1.0, atol=1e-9)


# --- known poses -------------------------------------------------------------------------------------------
def test_positions_standing_height_forward_and_right():
    s = decode_one("/VMC/Ext/Hmd/Pos", (0, 1.7, 0), (0, 0, 0, 1))
    np.testing.assert_allclose(s.position, [0, 0, 1.7], atol=1e-6)  # 1.7 m up
    np.testing.assert_allclose(s.quat, [1, 0, 0, 0], atol=1e-12)
    fwd = decode_one("/VMC/Ext/Con/Pos", (0, 0, 1), (0, 0, 0, 1))
    np.testing.assert_allclose(fwd.position, [1, 0, 0], atol=1e-6)  # Unity forward is our forward (+X)
    right = decode_one("/VMC/Ext/Con/Pos", (1, 0, 0), (0, 0, 0, 1))
    np.testing.assert_allclose(right.position, [0, -1, 0], atol=1e-6)  # Unity right is our -Y (we have +Y left)


def test_unity_yaw_90_is_a_right_turn_minus_90_about_our_z():
    h = math.sqrt(0.5)
    # Unity: +90 deg about Y (up) turns forward (0,0,1) to right (1,0,0), seen from above clockwise
    s = decode_one("/VMC/Ext/Hmd/Pos", (0, 1.6, 0), (0, h, 0, h))
    np.testing.assert_allclose(s.quat, [h, 0, 0, -h], atol=1e-7)  # -90 deg about our Z
    np.testing.assert_allclose(R(s) @ [1, 0, 0], [0, -1, 0], atol=1e-7)  # our forward turned to our right
    np.testing.assert_allclose(R(s) @ [0, 0, 1], [0, 0, 1], atol=1e-7)  # up stays up


def test_unity_pitch_and_roll():
    a = math.radians(30)
    c, sn = math.cos(a / 2), math.sin(a / 2)
    # Unity +30 deg about X (right): forward (0,0,1) -> (0, -sin, cos), the nose goes down
    pitch = decode_one("/VMC/Ext/Hmd/Pos", (0, 1.6, 0), (sn, 0, 0, c))
    np.testing.assert_allclose(R(pitch) @ [1, 0, 0], [math.cos(a), 0, -math.sin(a)], atol=1e-7)
    np.testing.assert_allclose(pitch.quat, [c, 0, sn, 0], atol=1e-7)  # +30 deg about our Y (left) is nose down
    # Unity +30 deg about Z (forward): up (0,1,0) -> (-sin, cos, 0), the top tilts to Unity's -X, the left
    roll = decode_one("/VMC/Ext/Hmd/Pos", (0, 1.6, 0), (0, 0, sn, c))
    np.testing.assert_allclose(R(roll) @ [0, 0, 1], [0, math.sin(a), math.cos(a)], atol=1e-7)  # toward +Y (left)
    np.testing.assert_allclose(R(roll) @ [1, 0, 0], [1, 0, 0], atol=1e-7)


def _msg(address: str, *args: object):
    b = OscMessageBuilder(address=address)
    for a in args:
        b.add_arg(a)
    return b.build()


def test_bundles_nested_local_forms_and_other_addresses():
    b = OscBundleBuilder(IMMEDIATELY)
    b.add_content(_msg("/VMC/Ext/T", 12.5))
    b.add_content(_msg("/VMC/Ext/Bone/Pos", "Hips", 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    inner = OscBundleBuilder(IMMEDIATELY)
    inner.add_content(_msg("/VMC/Ext/OK", 1))
    inner.add_content(_msg("/VMC/Ext/Tra/Pos/Local", "TRK-1", 0.0, 1.0, -0.2, 0.0, 0.0, 0.0, 1.0))
    b.add_content(inner.build())
    b.add_content(_msg("/VMC/Ext/Hmd/Pos", "HMD-1", 0.0, 1.7, 0.0, 0.0, 0.0, 0.0, 1.0))
    got = {s.serial: s for s in vmc.decode(b.build().dgram)}
    assert set(got) == {"TRK-1", "HMD-1"}
    assert (got["TRK-1"].kind, got["TRK-1"].local, got["TRK-1"].sender_time) == ("tra", True, 12.5)
    assert (got["HMD-1"].kind, got["HMD-1"].local, got["HMD-1"].sender_time) == ("hmd", False, 12.5)
    np.testing.assert_allclose(got["TRK-1"].position, [-0.2, 0, 1.0], atol=1e-6)  # 20 cm behind, 1 m up
    # a performer's avatar stream has no device messages: nothing, and no error
    only_bones = OscBundleBuilder(IMMEDIATELY)
    only_bones.add_content(_msg("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    only_bones.add_content(_msg("/VMC/Ext/Hmd/Posture", "x"))  # not a device address either
    assert vmc.decode(only_bones.build().dgram) == []
    # doubles and ints are numbers too (some senders use them)
    (d,) = vmc.decode(_msg("/VMC/Ext/Con/Pos", "C", 0, 1, 0, 0.0, 0.0, 0.0, 1).dgram)
    np.testing.assert_allclose(d.position, [0, 0, 1])


@pytest.mark.parametrize("datagram, words", [
    (b"\x00\x01garbage", "not an OSC packet"),
    (b"", "not an OSC packet"),
    (_msg("/VMC/Ext/Hmd/Pos", "H", 0.0, 1.7, 0.0).dgram, "expected (serial string, 7 numbers)"),
    (_msg("/VMC/Ext/Con/Pos", 3, 0.0, 1.7, 0.0, 0.0, 0.0, 0.0, 1.0).dgram, "expected (serial string, 7 numbers)"),
    (_msg("/VMC/Ext/Con/Pos", "C", "a", 1.7, 0.0, 0.0, 0.0, 0.0, 1.0).dgram, "expected (serial string, 7 numbers)"),
    (_msg("/VMC/Ext/Tra/Pos", "T", float("nan"), 1.7, 0.0, 0.0, 0.0, 0.0, 1.0).dgram, "non-finite"),
    (_msg("/VMC/Ext/Tra/Pos/Local", "T", 0.0, 1.7, 0.0, 0.0, 0.0, 0.0, 0.0).dgram, "norm 0"),
    (_msg("/VMC/Ext/T", "soon").dgram, "/VMC/Ext/T"),
])
def test_malformed_datagrams_are_one_line_value_errors(datagram, words):
    with pytest.raises(ValueError) as err:
        vmc.decode(datagram)
    text = str(err.value)
    assert words in text and "\n" not in text


# --- the device on a real socket ----------------------------------------------------------------------------
def _read_until(dev, n: int, seconds: float = 5.0) -> list:
    out: list = []
    end = time.monotonic() + seconds
    while len(out) < n and time.monotonic() < end:
        out += dev.read_many(0.1)
    return out


def test_device_receives_maps_serials_and_counts():
    port = free_udp_port()
    url = f"vmc-in://127.0.0.1:{port}?head=HMD-1&l_hand=CON-L&r_hand=CON-R&id=vr"
    dev = open_device(url)
    assert isinstance(dev, VmcInDevice) and dev.sites == ("head", "l_hand", "r_hand")
    assert dev.fileno() is not None  # the hub's selector can wait on it
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        q = np.array([1.0, 0.0, 0.0, 0.0])
        frames = []
        for k in range(20):
            z = 1.6 + 0.01 * k
            frames.append(vmc.encode_frame([
                vmc.DevicePose("hmd", "HMD-1", np.array([0.0, 0.0, z]), q),
                vmc.DevicePose("con", "CON-L", np.array([0.3, 0.3, 1.0]), q),
                vmc.DevicePose("con", "CON-R", np.array([0.3, -0.3, 1.0]), q),
                vmc.DevicePose("tra", "LHR-FOOT", np.array([0.0, 0.1, 0.05]), q),  # not in the URL
            ], sender_time=0.011 * k))
        frames.insert(5, b"#bundle\x00 broken")
        for f in frames:
            tx.sendto(f, ("127.0.0.1", port))
        got = _read_until(dev, 60)
        assert len(got) == 60
        by_site = {s: [x for x in got if x.extra["site"] == s] for s in dev.sites}
        assert {s: len(v) for s, v in by_site.items()} == {"head": 20, "l_hand": 20, "r_hand": 20}
        heads = by_site["head"]
        np.testing.assert_allclose([h.extra["position"][2] for h in heads], 1.6 + 0.01 * np.arange(20), atol=1e-6)
        np.testing.assert_allclose([h.device_time for h in heads], 0.011 * np.arange(20), atol=1e-6)
        np.testing.assert_allclose(by_site["r_hand"][0].extra["position"], [0.3, -0.3, 1.0], atol=1e-6)
        assert all(x.device_id == "vr" and x.t > 0 for x in got)
        assert dev.stats.decoded == 60 and dev.stats.bad_frame == 1 and dev.stats.errors == 1
        assert dev.unmapped == 20 and dev.serials_seen["LHR-FOOT"] == "tra"
        latest = dev.pose("head")
        assert latest is not None and latest.position[2] == pytest.approx(1.79, abs=1e-6)
        assert latest.t <= time.monotonic() and latest.serial == "HMD-1"
        with pytest.raises(KeyError):
            dev.pose("pelvis")

        # a serial sent in both forms is taken in the preferred one (default /Pos), once
        both = OscBundleBuilder(IMMEDIATELY)
        both.add_content(vmc.message("hmd", "HMD-1", [0.0, 0.0, 1.5], q, local=True))
        both.add_content(vmc.message("hmd", "HMD-1", [0.0, 0.0, 1.55], q))
        tx.sendto(both.build().dgram, ("127.0.0.1", port))
        (s,) = _read_until(dev, 1)
        assert s.extra["position"][2] == pytest.approx(1.55, abs=1e-6)
        tx.sendto(vmc.encode("hmd", "HMD-1", [0.0, 0.0, 1.4], q, local=True), ("127.0.0.1", port))
        tx.sendto(vmc.encode("hmd", "HMD-1", [0.0, 0.0, 1.45], q), ("127.0.0.1", port))
        (s,) = _read_until(dev, 1)
        assert s.extra["position"][2] == pytest.approx(1.45, abs=1e-6)  # the /Local one was passed over
    finally:
        tx.close()
        dev.close()


def test_device_takes_a_local_only_sender():
    port = free_udp_port()
    dev = open_device(f"vmc-in://127.0.0.1:{port}?head=H")
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        tx.sendto(vmc.encode("hmd", "H", [0.0, 0.0, 1.6], [1.0, 0.0, 0.0, 0.0], local=True), ("127.0.0.1", port))
        (s,) = _read_until(dev, 1)
        assert s.extra["site"] == "head" and s.extra["position"][2] == pytest.approx(1.6, abs=1e-6)
        assert s.device_time is None
    finally:
        tx.close()
        dev.close()


@pytest.mark.parametrize("url, words", [
    ("vmc-in://127.0.0.1:39540", "names no site"),
    ("vmc-in://127.0.0.1:39540?head=A&nose=B", "unknown parameter(s) nose"),
    ("vmc-in://127.0.0.1:39540?head=A&l_hand=A", "serial 'A' given for both"),
    ("vmc-in://localhost:39540?head=A", "is not an IP address"),
    ("vmc-in://127.0.0.1:port?head=A", "is not a number"),
])
def test_bad_urls_say_what_is_wrong(url, words):
    with pytest.raises(ValueError) as err:
        make_device(url)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_default_port_and_describe():
    dev = make_device("vmc-in://127.0.0.1?head=H&l_hand=L&local=1")
    assert dev.port == 39540 and dev.prefer_local
    assert dev.describe() == "vmc-in://127.0.0.1:39540?head=H&l_hand=L&local=1"
