"""Wire formats: vendor packets byte-exact, encode/decode round trips, fuzzed decoders."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.bno08x import protocol as rvc
from drivers.dualsense import protocol as ds
from drivers.moticon import protocol as mot
from drivers.xbus import protocol as xb
from drivers.xsens_can import protocol as xcan

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

MTI_PACKET = bytes.fromhex(
    "FA FF 36 31 10 20 02 DF C5 10 60 04 00 45 9D A0 40 20 0C BE DC 9A FA 3F 54 9F 37 41 1C BB 70"
    " 80 20 0C BB AA 5C 80 3B 8C 55 01 BB 81 33 00 E0 20 04 00 00 00 81 45"
)
RVC_PACKET = bytes.fromhex("AA AA DE 01 00 92 FF 25 08 8D FE EC FF D1 03 00 00 00 E7")


# --- Xbus ---------------------------------------------------------------------------------------------
def test_xbus_vendor_packet_byte_exact():
    msg = xb.decode(MTI_PACKET)
    assert msg.mid == xb.MID.MTData2 and msg.bid == 0xFF and len(msg.data) == 0x31
    d = xb.decode_mtdata2(msg.data)
    assert d.packet_counter == 0xDFC5
    assert d.sample_time_fine == 0x00459DA0
    assert d.acc == pytest.approx((-0.431, 0.831, 9.796), abs=1e-3)
    assert d.gyro is not None and max(abs(v) for v in d.gyro) < 0.01
    assert d.status == 0x81
    assert d.precision == xb.Precision.FLOAT32 and d.frame == xb.CoordFrame.ENU
    # re-encoding the decoded content gives the captured bytes back
    again = xb.encode(xb.MID.MTData2, xb.encode_mtdata2(d))
    assert again == MTI_PACKET


@pytest.mark.parametrize("prec", list(xb.Precision))
@pytest.mark.parametrize("frame", list(xb.CoordFrame))
def test_xbus_mtdata2_round_trip_all_precisions_and_frames(prec, frame):
    q = (0.9238795, 0.0, 0.3826834, 0.0)
    d = xb.MTData2(
        packet_counter=65535,
        sample_time_fine=123456789,
        quat=q,
        acc=(-0.5, 1.25, 9.81),
        free_acc=(0.1, -0.2, 0.3),
        gyro=(1.0, -2.0, 3.5),
        status=0x1234,
        precision=prec,
        frame=frame,
    )
    frame_bytes = xb.encode(xb.MID.MTData2, xb.encode_mtdata2(d))
    out = xb.decode_mtdata2(xb.decode(frame_bytes).data)
    tol = {
        xb.Precision.FLOAT32: 1e-6,
        xb.Precision.FP1220: 2e-6,
        xb.Precision.FP1632: 1e-9,
        xb.Precision.FLOAT64: 1e-15,
    }[prec]
    for name in ("quat", "acc", "free_acc", "gyro"):
        assert getattr(out, name) == pytest.approx(getattr(d, name), abs=tol)
    assert (out.packet_counter, out.sample_time_fine, out.status) == (65535, 123456789, 0x1234)
    assert out.precision == prec and out.frame == frame


def test_xbus_fp1632_layout_fraction_then_integer():
    # -1.5 = integer part -2, fraction 0.5 -> fraction word 0x80000000 then int16 0xFFFE
    b = xb.encode_mtdata2(xb.MTData2(acc=(-1.5, 0.0, 2.25), precision=xb.Precision.FP1632))
    assert b[3:9] == bytes.fromhex("80000000FFFE")
    assert xb.decode_mtdata2(b).acc == (-1.5, 0.0, 2.25)


def test_xbus_extended_length_and_config_messages():
    payload = bytes(range(256)) * 2
    f = xb.encode(0x36, payload)
    assert f[3] == 0xFF and xb.decode(f).data == payload
    cfg = xb.default_output_configuration(100, xb.Precision.FP1220, xb.CoordFrame.NED)
    assert xb.decode_output_configuration(xb.encode_output_configuration(cfg)) == cfg
    assert xb.encode(xb.MID.GoToConfig) == bytes.fromhex("FAFF3000D1")  # the well-known GoToConfig bytes


def _xbus_frames(n: int, seed: int = 0) -> list[bytes]:
    rng = random.Random(seed)
    return [
        xb.encode(
            0x36,
            xb.encode_mtdata2(xb.MTData2(packet_counter=k, quat=(1.0, 0, 0, 0), acc=(rng.random(), 0.0, 9.8))),
        )
        for k in range(n)
    ]


@FUZZ
@given(st.binary(max_size=600))
def test_xbus_parser_random_bytes_never_raise(junk):
    p = xb.XbusStreamParser()
    for m in p.feed(junk):
        try:
            xb.decode_mtdata2(m.data)
        except xb.XbusError:
            pass
    # after any junk, a flush of clean frames is decoded again (resynchronisation)
    clean = _xbus_frames(3)
    got = p.feed(b"".join(clean) * 2)
    assert got[-3:] == [xb.decode(f) for f in clean]


@FUZZ
@given(st.data())
def test_xbus_parser_mutated_stream_counts_and_resyncs(data):
    frames = _xbus_frames(6, data.draw(st.integers(0, 100)))
    k = data.draw(st.integers(1, 4))  # corrupt frame k (not first, not last)
    bad = bytearray(frames[k])
    pos = data.draw(st.integers(1, len(bad) - 1))
    bad[pos] ^= data.draw(st.integers(1, 255))
    stream = b"".join(frames[:k]) + bytes(bad) + b"".join(frames[k + 1 :])
    p = xb.XbusStreamParser()
    got = p.feed(stream) + p.feed(b"".join(frames))  # a corrupted length may hold the tail back
    counters = [m.data[3:5] for m in got if m.mid == 0x36 and len(m.data) > 5]
    assert len(got) >= 10  # at most the corrupted frame is lost
    assert p.bad_checksum + p.resyncs >= 1 or bytes(bad) in [xb.encode(m.mid, m.data, m.bid) for m in got]
    assert counters[-6:] == [f[7:9] for f in frames]


@FUZZ
@given(st.binary(max_size=300))
def test_xbus_mtdata2_decoder_only_raises_xbus_error(payload):
    try:
        xb.decode_mtdata2(payload)
    except xb.XbusError:
        pass


# --- BNO08x RVC ---------------------------------------------------------------------------------------
def test_rvc_datasheet_packet_byte_exact():
    f = rvc.decode(RVC_PACKET)
    assert f.index == 0xDE
    assert (f.yaw_deg, f.pitch_deg, f.roll_deg) == (0.01, -1.10, 20.85)
    assert f.acc_mg == (-371.0, -20.0, 977.0)
    assert rvc.encode(f) == RVC_PACKET


@FUZZ
@given(
    st.integers(0, 255),
    st.floats(-179.99, 180),
    st.floats(-90, 90),
    st.floats(-179.99, 180),
    st.tuples(*[st.floats(-8000, 8000)] * 3),
)
def test_rvc_round_trip(i, yaw, pitch, roll, acc):
    f = rvc.decode(rvc.encode(rvc.RvcFrame(i, yaw, pitch, roll, acc)))
    assert f.index == i
    for a, b in ((f.yaw_deg, yaw), (f.pitch_deg, pitch), (f.roll_deg, roll)):
        assert abs((a - b + 180) % 360 - 180) <= 0.0051
    assert np.allclose(f.acc_mg, acc, atol=0.51)


@FUZZ
@given(st.binary(max_size=400), st.data())
def test_rvc_parser_fuzz_random_and_mutated(junk, data):
    p = rvc.RvcStreamParser()
    p.feed(junk)
    frames = [rvc.encode(rvc.RvcFrame(k, k, 0, 0, (0, 0, 1000))) for k in range(5)]
    bad = bytearray(frames[2])
    bad[data.draw(st.integers(2, 18))] ^= data.draw(st.integers(1, 255))
    got = p.feed(b"".join(frames[:2]) + bytes(bad) + b"".join(frames[3:]) + b"".join(frames))
    assert [f.index for f in got[-5:]] == [0, 1, 2, 3, 4]
    assert p.bad_checksum >= 1 or any(f == rvc.decode(bytes(bad)) for f in got if True)


# --- Xsens CAN ----------------------------------------------------------------------------------------
def test_can_round_trip_and_offsets():
    g = xcan.CanGroup(
        sample_time_us=4_000_000_123,
        counter=65535,
        status=0x81,
        quat=(0.7071, 0.0, 0.7071, 0.0),
        gyro=(1.0, -2.0, 0.5),
        acc=(0.0, 0.1, 9.81),
        free_acc=(0.01, 0.02, -0.03),
    )
    frames = xcan.encode(g, id_offset=0x100)
    assert [fid for fid, _ in frames] == [0x105, 0x106, 0x111, 0x121, 0x132, 0x134, 0x135]
    assert frames[1][1] == b"\xff\xff"  # big-endian uint16 counter
    asm = xcan.GroupAssembler()
    out = [asm.push(*xcan.decode(fid, data, 0x100)) for fid, data in frames + frames]
    groups = [o for o in out if o is not None]
    assert groups, "second group start must flush the first"
    d = groups[0]
    assert d.sample_time_us == 4_000_000_123 and d.counter == 65535 and d.status == 0x81
    assert d.quat == pytest.approx(g.quat, abs=1 / 32767) and d.acc == pytest.approx(g.acc, abs=1 / 256)
    assert d.gyro == pytest.approx(g.gyro, abs=1 / 512) and d.free_acc == pytest.approx(g.free_acc, abs=1 / 256)
    # once the layout is learned, the next group completes on its last frame (no extra latency)
    assert out[-1] is not None
    assert xcan.decode(0x7FF, b"", 0) is None  # other traffic on the bus is ignored


@FUZZ
@given(st.integers(0, 0x7FF), st.binary(max_size=8))
def test_can_decoder_fuzz(fid, payload):
    try:
        r = xcan.decode(fid, payload)
    except xcan.CanDecodeError:
        return
    if r is not None:
        xcan.GroupAssembler().push(*r)


# --- DualSense ----------------------------------------------------------------------------------------
def test_dualsense_report_layout_and_round_trip():
    d = ds.DsInput(
        seq=200,
        gyro_raw=(1, -2, 300),
        accel_raw=(-8192, 0, 8192),
        timestamp=0xFFFFFFF0,
        battery_pct=75.0,
        charging=True,
    )
    b = ds.encode_input_report(d)
    assert len(b) == 64 and b[0] == 1 and b[7] == 200
    assert b[16:18] == b"\x01\x00" and b[28:32] == b"\xf0\xff\xff\xff"
    assert ds.decode_input_report(b) == d
    cal = ds.DsCalibration(
        gyro_bias=(3, -4, 5),
        gyro_plus=(8000, 8100, 8200),
        gyro_minus=(-8000, -8100, -8200),
        acc_plus=(8200, 8100, 8300),
        acc_minus=(-8100, -8200, -8000),
    )
    cb = ds.encode_calibration(cal)
    assert len(cb) == 41 and cb[0] == 5
    assert ds.decode_calibration(cb) == cal
    scale, bias = cal.acc_scale_bias()
    assert (8200 - bias[0]) * scale[0] == pytest.approx(9.80665)
    assert cal.gyro_scale()[0] * (abs(8000 - 3) + abs(-8000 - 3)) == pytest.approx(math.radians(1080))


@FUZZ
@given(st.binary(max_size=80))
def test_dualsense_decoders_fuzz(b):
    for fn in (ds.decode_input_report, ds.decode_calibration):
        try:
            fn(b)
        except ds.DualSenseError:
            pass


# --- Moticon ------------------------------------------------------------------------------------------
def _insole(t: float, fl: float, fr: float) -> mot.InsoleFrame:
    rng = np.random.default_rng(1)
    return mot.InsoleFrame(
        t,
        rng.normal(size=(2, 3)),
        rng.normal(size=(2, 3)),
        np.array([[0.0, -0.3], [0.0, 0.3]]),
        np.abs(rng.normal(size=(2, 16))),
        np.array([fl, fr]),
    )


def test_moticon_round_trip_and_layout():
    f = _insole(12.345, 700.0, 0.0)
    g = mot.decode(mot.encode(f))
    assert len(mot.LAYOUT) == mot.N_FIELDS == 51
    assert g.time == pytest.approx(12.345)
    for a, b in (
        (g.acc_g, f.acc_g),
        (g.pressure, f.pressure),
        (g.total_force, f.total_force),
        (g.cop, f.cop),
    ):
        assert np.allclose(a, b, atol=1e-4)


@FUZZ
@given(st.binary(max_size=600))
def test_moticon_decoder_fuzz(b):
    try:
        mot.decode(b)
    except mot.MoticonError:
        pass


def test_contact_detector_hysteresis_and_min_duration():
    det = mot.ContactDetector(body_weight_n=700.0, min_duration=0.03)
    cop = np.array([[0.0, -0.3], [0.0, 0.3]])
    dt = 0.01
    seq = [0] * 5 + [40] * 2 + [0] * 5 + [300] * 10 + [30] * 10 + [10] * 10  # 5% = 35 N on, 3% = 21 N off
    states = [bool(det.update(k * dt, np.array([f, f]), cop)[0]) for k, f in enumerate(seq)]
    assert not any(states[:12])  # a 20 ms bump above threshold is not a step
    assert all(states[15:22]) and all(states[22:32])  # 30 N is inside the hysteresis band: stays on
    assert not any(states[-5:])
    last = det.update(1.0, np.array([300.0, 300.0]), cop)
    assert list(last) in ([True, False, False, True], [False, False, False, False])
