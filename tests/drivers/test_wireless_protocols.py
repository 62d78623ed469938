"""Movella DOT BLE payloads and x-IMU3 data messages: a published packet of each decoded
byte for byte, round trips, and our x-IMU3 bytes read by x-io's own parser."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from drivers.movella_dot import protocol as dot
from drivers.ximu3 import protocol as x3

# Two short-payload notifications (characteristic 0x2004, payload mode 6, free acceleration)
# captured from a DOT and printed with their decoded values in the docstring of
# turn_on_measurement_service.py, github.com/protobioengineering/xsens-dot-python-examples.
DOT_CAPTURED = (
    (bytes.fromhex("d8052244 af964040 6b2aa740 5add14c0 00000000"), 1143080408, (3.009197, 5.223928, -2.3260102)),
    (bytes.fromhex("f3462244 0da53c40 9c13a640 f010 09c0 00000000"), 1143097075, (2.947574, 5.1898937, -2.1416588)),
)


@pytest.mark.parametrize("data,ts,free", DOT_CAPTURED)
def test_dot_captured_notification_byte_exact(data, ts, free):
    assert len(data) == 20  # the short payload characteristic's length
    m = dot.decode(data, dot.MODE_FREE_ACCELERATION)
    assert m.timestamp_us == ts == int.from_bytes(data[0:4], "little")
    assert m.quat is None
    np.testing.assert_allclose(m.free_acc, free, rtol=1e-6)
    assert m.free_acc == struct.unpack("<3f", data[4:16])
    assert data[16:] == bytes(4)  # padding
    assert dot.encode(m, dot.MODE_FREE_ACCELERATION) == data
    # 16.667 ms apart: the 60 Hz real-time rate on the sensor's microsecond clock
    assert DOT_CAPTURED[1][1] - DOT_CAPTURED[0][1] == 16_667


def test_dot_complete_quaternion_layout_and_round_trip():
    m = dot.DotMeasurement(0x01020304, (0.5, -0.5, 0.5, -0.5), (1.0, -2.0, 0.25))
    b = dot.encode(m, dot.MODE_COMPLETE_QUATERNION)
    assert len(b) == 40 and b[32:] == bytes(8)  # medium payload, 32 bytes of data, zero padded
    assert b[:4] == bytes((4, 3, 2, 1))
    assert b[4:8] == struct.pack("<f", 0.5) and b[28:32] == struct.pack("<f", 0.25)
    assert dot.decode(b) == m
    assert dot.characteristic_for(dot.MODE_COMPLETE_QUATERNION) == "15172003-4947-11e9-8646-d663bd873d93"
    rng = np.random.default_rng(0)
    for mode in dot.MODES:
        for _ in range(50):
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            m = dot.DotMeasurement(int(rng.integers(0, 1 << 32)), tuple(np.float32(q).tolist()),
                                   tuple(np.float32(rng.normal(size=3) * 20).tolist()), 3, 1, 2)
            d = dot.decode(dot.encode(m, mode), mode)
            assert d.timestamp_us == m.timestamp_us
            assert (d.quat == m.quat) if dot.MODES[mode].has_quat else d.quat is None
            assert (d.free_acc == m.free_acc) if dot.MODES[mode].has_free_acc else d.free_acc is None


def test_dot_control_and_battery_characteristics():
    start = dot.encode_control(dot.DotControl(action=1, payload_mode=dot.MODE_COMPLETE_QUATERNION))
    assert start == b"\x01\x01\x03"  # measurement, start, complete quaternion
    assert dot.decode_control(start).streaming
    assert dot.encode_battery(dot.DotBattery(87, True)) == b"\x57\x01"
    assert dot.decode_battery(b"\x57\x01") == dot.DotBattery(87, True)
    for bad, fn in ((b"\x01\x01", dot.decode_control), (b"\x65\x00", dot.decode_battery), (b"", dot.decode_battery)):
        with pytest.raises(dot.DotError):
            fn(bad)
    with pytest.raises(dot.DotError):
        dot.decode(bytes(40))  # an all-zero quaternion: not a sample any DOT sends
    with pytest.raises(dot.DotError):
        dot.decode(bytes(10))
    assert dot.is_dot_advertisement("Movella DOT") and dot.is_dot_advertisement(None, (0x0886,))
    assert not dot.is_dot_advertisement("Polar H10")


# x-IMU3 User Manual v0.11 (x-io Technologies, April 2022), section 8.2.2, inertial message
# example: timestamp 1 s, gyroscope 0, accelerometer (0, 0, 1) g.
X3_INERTIAL_BINARY = bytes.fromhex(
    "C9 40420F0000000000 00000000 00000000 00000000 00000000 00000000 0000803F 0A")
X3_INERTIAL_ASCII = b"I,1000000,0.0000,0.0000,0.0000,0.0000,0.0000,1.0000\r\n"


def test_ximu3_manual_inertial_example_byte_exact():
    for raw in (X3_INERTIAL_BINARY, X3_INERTIAL_ASCII):
        m = x3.decode(raw)
        assert m == x3.Message(x3.INERTIAL, 1_000_000, (0.0, 0.0, 0.0, 0.0, 0.0, 1.0))
    assert X3_INERTIAL_BINARY[0] == 0x80 + ord("I")
    assert int.from_bytes(X3_INERTIAL_BINARY[1:9], "little") == 1_000_000
    assert x3.encode(x3.decode(X3_INERTIAL_BINARY)) == X3_INERTIAL_BINARY
    assert x3.encode(x3.decode(X3_INERTIAL_ASCII), binary=False) == X3_INERTIAL_ASCII


def test_ximu3_byte_stuffing_and_round_trip():
    # a timestamp whose bytes hold the terminator and the escape: stuffed, and back
    m = x3.Message(x3.QUATERNION, 0x0A_DB_0A, (1.0, 0.0, 0.0, 0.0))
    b = x3.encode(m)
    assert b.count(b"\n") == 1 and b.endswith(b"\n") and b"\xdb\xdc" in b and b"\xdb\xdd" in b
    assert x3.decode(b) == m
    rng = np.random.default_rng(1)
    for kind, n in ((x3.INERTIAL, 6), (x3.QUATERNION, 4), (x3.BATTERY, 3)):
        for _ in range(50):
            vals = tuple(np.float32(rng.normal(size=n) * 100).tolist())
            m = x3.Message(kind, int(rng.integers(0, 1 << 63)), vals)
            assert x3.decode(x3.encode(m)) == m
            a = x3.decode(x3.encode(m, binary=False))
            assert a.kind == kind and a.timestamp_us == m.timestamp_us
            np.testing.assert_allclose(a.values, vals, atol=5.1e-5)  # four decimals
    msgs, rest = x3.split(X3_INERTIAL_ASCII + X3_INERTIAL_BINARY + b"I,2")
    assert len(msgs) == 2 and rest == b"I,2"
    for bad in (b"", b"\xc9\x00\n", b"Z,1,2\r\n", b"I,1,2,3\r\n", b"\xc9" + b"\xdb\x00" * 16 + b"\n",
                b"Q,1,nan,0,0,0\r\n"):
        with pytest.raises(x3.Ximu3Error):
            x3.decode(bad)


def test_ximu3_our_bytes_are_read_by_x_ios_parser():
    """The twin's bytes, sent over loopback UDP to x-io's ximu3 package, come out as sent."""
    ximu3 = pytest.importorskip("ximu3")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    conn = ximu3.Connection(ximu3.UdpConnectionConfig("127.0.0.1", 9, port))
    got: list[tuple] = []
    errors: list[int] = []
    conn.add_inertial_callback(lambda m: got.append(("I", m.timestamp, m.gyroscope_x, m.gyroscope_y, m.gyroscope_z,
                                                     m.accelerometer_x, m.accelerometer_y, m.accelerometer_z)))
    conn.add_quaternion_callback(lambda m: got.append(("Q", m.timestamp, m.w, m.x, m.y, m.z)))
    conn.add_battery_callback(lambda m: got.append(("B", m.timestamp, m.percentage, m.voltage, m.charging_status)))
    conn.add_receive_error_callback(errors.append)
    conn.open()
    sent = [x3.Message(x3.INERTIAL, 0x0A0ADB, (1.5, -2.0, 3.0, 0.0, 0.1, 1.0)),
            x3.Message(x3.QUATERNION, 2_000_000, (0.5, 0.5, -0.5, 0.5)),
            x3.Message(x3.BATTERY, 3_000_000, (87.5, 3.75, 1.0))]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(X3_INERTIAL_BINARY + X3_INERTIAL_ASCII, ("127.0.0.1", port))
            s.sendto(b"".join(x3.encode(m) for m in sent), ("127.0.0.1", port))
            s.sendto(b"".join(x3.encode(m, binary=False) for m in sent), ("127.0.0.1", port))
            deadline = time.monotonic() + 5.0
            while len(got) < 8 and time.monotonic() < deadline:
                time.sleep(0.02)
    finally:
        conn.close()
    assert errors == []
    assert got[0] == got[1] == ("I", 1_000_000, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for k, m in enumerate(sent * 2):
        kind, ts, *vals = got[2 + k]
        assert kind == m.kind and ts == m.timestamp_us
        np.testing.assert_allclose(vals, m.values, rtol=1e-6)
