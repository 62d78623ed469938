"""The factory behind ``--stream``, the frame conversion's known answers, and the replay pacer."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from app.streams import (
    add_stream_arguments,
    is_loopback,
    make_stream_sinks,
    parse_stream_spec,
    sinks_from_args,
    stream_summary,
)
from app.streams.pacing import Pacer
from app.streams.unity import rot_to_unity, unity_euler_deg, unity_quat, vec_to_unity
from app.streams.vmc import VmcSink
from app.streams.vrchat import VrchatSink
from inference.body.rotations import matrix_about_axis


def test_spec_parsing():
    assert parse_stream_spec(None) == [] and parse_stream_spec("") == []
    assert parse_stream_spec("lsl, VMC:39540,vrchat") == [("lsl", None), ("vmc", 39540), ("vrchat", None)]
    assert parse_stream_spec(["vmc", "vmc:39540"]) == [("vmc", None), ("vmc", 39540)]  # two avatar apps


@pytest.mark.parametrize("spec, message", [
    ("lsl,osc", "unknown stream 'osc'; valid: lsl, vmc, vrchat"),
    ("lsl:16571", "lsl takes no port"),
    ("vmc:abc", "the port must be a number"),
    ("vmc:0", "is not a UDP port"),
    ("vmc,vmc", "given twice"),
])
def test_spec_errors_are_one_line(spec, message):
    with pytest.raises(ValueError) as e:
        make_stream_sinks(spec)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_sinks_default_to_this_machine_and_their_ports():
    sinks = make_stream_sinks("vmc,vrchat:9100")
    try:
        assert isinstance(sinks[0], VmcSink) and isinstance(sinks[1], VrchatSink)
        assert [s["target"] for s in stream_summary(sinks)] == ["127.0.0.1:39539", "127.0.0.1:9100"]
    finally:
        for s in sinks:
            s.close()
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("192.168.1.20") and not is_loopback("0.0.0.0") and not is_loopback("studio-pc")


def test_cli_arguments_for_any_command():
    p = argparse.ArgumentParser()
    add_stream_arguments(p, replay=True)
    args = p.parse_args(["--stream", "vrchat:9123", "--stream-host", "127.0.0.2", "--stream-speed", "2"])
    assert args.stream_speed == 2.0
    (sink,) = sinks_from_args(args)
    sink.close()
    assert sink.summary()["target"] == "127.0.0.2:9123"
    assert sinks_from_args(p.parse_args([])) == []


def test_unity_frame_known_answers():
    # forward, left, up -> Unity +Z, -X, +Y
    np.testing.assert_allclose(vec_to_unity(np.eye(3)), [[0, 0, 1], [-1, 0, 0], [0, 1, 0]], atol=1e-12)
    # turning left by 90 deg (about our up) is a yaw of -90 deg about Unity's +Y (its yaw turns right)
    R = matrix_about_axis(np.array([0.0, 0.0, 1.0]), np.pi / 2)
    np.testing.assert_allclose(unity_euler_deg(rot_to_unity(R)), [0, -90, 0], atol=1e-9)
    np.testing.assert_allclose(unity_quat(rot_to_unity(R)), [0, -np.sqrt(0.5), 0, np.sqrt(0.5)], atol=1e-12)
    # pitching the nose down (about our left axis, +) is +X in Unity (its +X pitch looks down)
    R = matrix_about_axis(np.array([0.0, 1.0, 0.0]), np.radians(30))
    np.testing.assert_allclose(unity_euler_deg(rot_to_unity(R)), [30, 0, 0], atol=1e-9)


def test_pacer_holds_frames_to_real_time_times_the_speed():
    now = [100.0]
    slept = []

    def sleep(dt: float) -> None:
        slept.append(dt)
        now[0] += dt

    p = Pacer(2.0, clock=lambda: now[0], sleep=sleep)
    p(50.0)
    p(51.0)  # due 0.5 s after the first
    now[0] += 0.2  # the poser took a while: less to wait
    p(52.0)
    assert slept == pytest.approx([0.5, 0.3])
    assert p.to_monotonic(54.0) == pytest.approx(102.0)
    fast = Pacer(0.0, clock=lambda: now[0], sleep=sleep)
    fast(10.0)
    fast(20.0)
    assert len(slept) == 2 and fast.to_monotonic(20.0) == pytest.approx(now[0] + 10.0)
    with pytest.raises(ValueError, match=">= 0"):
        Pacer(-1)
