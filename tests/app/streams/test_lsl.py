"""LSL: an inlet in this process, resolving the streams by name as LabRecorder would,
gets the poses the pipeline emitted (values and sensor-time stamps on the LSL clock),
the channel layout from the stream header, the calibrated sensors and the markers."""

from __future__ import annotations

import time
import uuid
import xml.etree.ElementTree as ET

import numpy as np
import pytest

pylsl = pytest.importorskip("pylsl")

from app.streams import make_stream_sinks  # noqa: E402
from app.streams.lsl import LslSink, lsl_clock_offset  # noqa: E402
from inference.body.rotations import quat_to_matrix  # noqa: E402
from inference.body.skeleton import SEGMENTS, SITES  # noqa: E402

from .conftest import run_pipeline  # noqa: E402


def open_inlet(name: str) -> pylsl.StreamInlet:
    found = pylsl.resolve_byprop("name", name, minimum=1, timeout=10.0)
    assert len(found) == 1, f"stream {name!r}: found {len(found)}"
    inlet = pylsl.StreamInlet(found[0])
    inlet.open_stream(timeout=10.0)
    return inlet


def pull(inlet: pylsl.StreamInlet, n: int, timeout: float = 10.0) -> tuple[list, np.ndarray]:
    samples: list = []
    stamps: list = []
    end = time.monotonic() + timeout
    while len(samples) < n and time.monotonic() < end:
        s, t = inlet.pull_chunk(timeout=0.2)
        samples += s
        stamps += t
    return samples, np.array(stamps)


def channels(inlet: pylsl.StreamInlet) -> list[tuple[str, str, str]]:
    root = ET.fromstring(inlet.info(timeout=10.0).as_xml())
    return [(c.findtext("label"), c.findtext("unit"), c.findtext("type"))
            for c in root.findall("./desc/channels/channel")]


def test_lsl_streams_carry_what_the_pipeline_emitted(suit):
    prefix = f"imucap-test-{uuid.uuid4().hex[:8]}"
    (sink,) = make_stream_sinks("lsl", lsl_prefix=prefix)
    assert isinstance(sink, LslSink)
    body, sensors, markers = (open_inlet(f"{prefix} {k}") for k in ("body", "sensors", "markers"))
    time.sleep(0.5)  # let the inlets' connections settle before the first sample
    poses, pipe = run_pipeline(suit, [sink])
    pipe.event(poses[-1].t + 0.01, "marker", "step on the plate")
    assert len(poses) > 40

    # the body: header, values, stamps
    info = body.info(timeout=10.0)
    assert info.type() == "MoCap" and info.nominal_srate() == 20.0 and info.name() == f"{prefix} body"
    chans = channels(body)
    assert len(chans) == info.channel_count() == 24 * 4 + 3 + 24 * 3 + 4
    assert chans[:5] == [("pelvis_qw", "quaternion", "OrientationA"), ("pelvis_qx", "quaternion", "OrientationB"),
                         ("pelvis_qy", "quaternion", "OrientationC"), ("pelvis_qz", "quaternion", "OrientationD"),
                         ("l_thigh_qw", "quaternion", "OrientationA")]
    assert chans[96:99] == [("root_x", "meters", "PositionX"), ("root_y", "meters", "PositionY"),
                            ("root_z", "meters", "PositionZ")]
    assert chans[99 + 3 * 6] == ("spine2_x", "meters", "PositionX")
    assert [c[0] for c in chans[-4:]] == ["contact_l_heel", "contact_l_toe", "contact_r_heel", "contact_r_toe"]
    samples, stamps = pull(body, len(poses))
    assert len(samples) == len(poses)
    x = np.array(samples)
    q = x[:, :96].reshape(-1, 24, 4)
    R = np.stack([p.pose.rot for p in poses])
    np.testing.assert_allclose(quat_to_matrix(q), R, atol=2e-6)
    np.testing.assert_allclose(x[:, 96:99], np.stack([p.pose.root for p in poses]), atol=2e-6)
    J = np.stack([p.pose.joints for p in poses])
    np.testing.assert_allclose(x[:, 99:171].reshape(-1, 24, 3), J, atol=2e-6)
    assert np.ptp(J, axis=0).max() > 0.2  # a moving body
    np.testing.assert_array_equal(x[:, 171:] > 0.5, np.stack([p.pose.contacts for p in poses]))
    # stamped with the sensors' time, moved onto the LSL clock by one offset
    np.testing.assert_allclose(stamps, np.array([p.t for p in poses]) + sink.offset, atol=1e-6)
    assert abs(sink.offset - lsl_clock_offset(pylsl.local_clock)) < 1e-3

    # the sensors: the calibrated measurement of every site at 60 Hz, after calibration
    cal = pipe.calibration
    assert [c[0] for c in channels(sensors)[:7]] == ["pelvis_qw", "pelvis_qx", "pelvis_qy", "pelvis_qz",
                                                     "pelvis_ax", "pelvis_ay", "pelvis_az"]
    s, st = pull(sensors, sink.counts["sensors"])
    assert len(s) == sink.counts["sensors"] > 100
    by_t = {round(f.t + sink.offset, 6): f for f in suit.frames}
    for k in (0, len(s) // 2, len(s) - 1):
        f = by_t[round(st[k], 6)]
        Rw, aw = cal.apply(f.quat, f.free_acc, f.acc, sites=f.sites)
        got = np.array(s[k]).reshape(len(SITES), 7)
        np.testing.assert_allclose(quat_to_matrix(got[:, :4]), Rw, atol=2e-6)
        np.testing.assert_allclose(got[:, 4:], aw, atol=1e-4)

    # the markers: the calibration and the marker, at their session times
    m, mt = pull(markers, 2)
    assert [v[0] for v in m] == ["calibration: took effect", "marker: step on the plate"]
    assert mt[1] == pytest.approx(poses[-1].t + 0.01 + sink.offset, abs=1e-6)
    pipe.close()
    assert sink.body is None


def test_layouts_name_every_segment_and_site():
    from app.streams.lsl import body_channels, sensor_channels

    labels = [c[0] for c in body_channels()]
    assert len(set(labels)) == len(labels) and all(f"{s}_qw" in labels and f"{s}_z" in labels for s in SEGMENTS)
    assert len(sensor_channels()) == 7 * len(SITES)


def test_clock_offset_trusts_the_least_disturbed_reading():
    # monotonic reads around each local_clock read; the second pair is the tightest
    ticks = iter([0.0, 1.0, 2.0, 2.1, 5.0, 6.0])
    lsl = iter([1000.7, 1002.05, 1005.2])  # offsets 1000.2, 1000.0, 999.7
    offset = lsl_clock_offset(lambda: next(lsl), lambda: next(ticks), tries=3)
    assert offset == pytest.approx(1000.0)


def test_confidence_stream_opens_with_the_first_spread_and_carries_it(walk_poses):
    import dataclasses

    prefix = f"imucap-test-{uuid.uuid4().hex[:8]}"
    sink = LslSink(prefix, sensors=False, markers=False)
    sink.on_pose(walk_poses[0])  # no spread: no confidence stream
    assert sink.confidence is None and "confidence" not in sink.names
    rng = np.random.default_rng(5)
    with_spread = [dataclasses.replace(p, pose=dataclasses.replace(p.pose, spread_deg=rng.uniform(0, 30, 24),
                                                                   root_spread_m=float(rng.uniform(0, 0.2))))
                   for p in walk_poses[1:]]
    sink.on_pose(with_spread[0])
    inlet = open_inlet(f"{prefix} confidence")
    info = inlet.info(timeout=10.0)
    assert info.channel_count() == 25 and info.nominal_srate() == 20.0
    chans = channels(inlet)
    assert chans[0] == ("pelvis_spread", "degrees", "Spread") and chans[-1] == ("root_spread", "meters", "Spread")
    time.sleep(0.5)
    for p in with_spread[1:]:
        sink.on_pose(p)
    samples, stamps = pull(inlet, len(with_spread) - 1)
    assert len(samples) == len(with_spread) - 1
    x = np.array(samples)
    np.testing.assert_allclose(x[:, :24], np.stack([p.pose.spread_deg for p in with_spread[1:]]), atol=1e-4)
    np.testing.assert_allclose(x[:, 24], [p.pose.root_spread_m for p in with_spread[1:]], atol=1e-6)
    np.testing.assert_allclose(stamps, np.array([p.t for p in with_spread[1:]]) + sink.offset, atol=1e-6)
    assert sink.counts["confidence"] == len(with_spread)
    sink.close()
