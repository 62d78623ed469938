"""Hub under packet loss: with the app's interpolating resampler a short burst of lost
packets is bridged (slerp across it), a long one stays a gap; the hold keeps marking
every lost stretch missing. Deterministic: samples pushed, the poll time given."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers._math import quat_from_euler_zyx
from drivers.base import Sample
from drivers.hub import Hub, Interpolation

resample = pytest.importorskip("inference.signals.resample")


def _dev():
    return drivers.make_device("bno08x-rvc:///dev/null-loss")


def _stream(hub: Hub, lost: set[int], n: int = 300) -> None:
    """100 Hz samples whose yaw is their time; the packets in ``lost`` never arrive, and
    the one after a loss says how many went missing (as the driver's counter check does)."""
    run = 0
    for k in range(n):
        if k in lost:
            run += 1
            continue
        t = 1.0 + k / 100
        q = quat_from_euler_zyx(t, 0.0, 0.0)
        s = Sample(t, None, "x", k & 0xFF, q, np.array([t, 0.0, 0.0]), np.array([0, 0, 9.81]), np.zeros(3))
        if run:
            s.extra["lost_before"] = run
            run = 0
        hub.push("pelvis", s)


def _poll(hub: Hub) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    hub._next_index = 61  # the grid from t = 1.0167
    frames = hub.poll(now=3.9)
    t = np.array([f.t for f in frames])
    yaw = np.array([2 * np.arctan2(f.quat[0, 3], f.quat[0, 0]) for f in frames])
    return t, yaw, np.array([f.present[0] for f in frames])


def _hub(**kw) -> Hub:
    return Hub({"pelvis": _dev()}, latency=0.0, staleness=0.05, max_backlog=5, queue_size=1024, **kw)


def test_bursts_of_lost_packets_are_interpolated_across():
    rng = np.random.default_rng(0)
    lost: set[int] = set()
    for start in rng.choice(np.arange(10, 280), 15, replace=False):
        lost.update(range(int(start), int(start) + int(rng.integers(1, 8))))  # bursts of 1-7 packets
    hub = _hub(interpolation=Interpolation(resample.slerp_unit))
    _stream(hub, lost)
    t, yaw, present = _poll(hub)
    inside = t < 3.95
    assert present[inside].all(), f"{(~present[inside]).sum()} grid frames lost to bursts of <= 70 ms"
    assert np.allclose(yaw[inside], t[inside], atol=1e-6)  # slerp across the burst is exact here


def test_a_long_gap_stays_a_gap_with_the_resampler():
    hub = _hub(interpolation=Interpolation(resample.slerp_unit))
    _stream(hub, set(range(100, 125)))  # 250 ms
    t, _, present = _poll(hub)
    gap = (t > 1.995) & (t < 2.245)
    assert not present[gap].any() and present[(t < 1.99) | ((t > 2.25) & (t < 3.95))].all()


def test_fill_gap_bounds_what_is_bridged():
    hub = _hub(interpolation=Interpolation(resample.slerp_unit), fill_gap=0.03)
    _stream(hub, set(range(100, 105)))  # 60 ms between the samples either side
    t, _, present = _poll(hub)
    assert not present[(t > 1.995) & (t < 2.045)].any()


def test_the_hold_still_marks_lost_packets_missing():
    hub = _hub()
    _stream(hub, set(range(100, 103)))
    t, _, present = _poll(hub)
    assert not present[(t > 1.995) & (t < 2.025)].any() and present[(t < 1.99) | ((t > 2.035) & (t < 3.95))].all()
