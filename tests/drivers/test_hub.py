"""Hub: clock fit, grid, gaps, bounded queues; deterministic (samples pushed, clock given)."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers._math import quat_from_euler_zyx
from drivers.base import Sample
from drivers.hub import ClockModel, Hub, Interpolation


def _dev(name="x"):
    return drivers.make_device(f"bno08x-rvc:///dev/null-{name}")


def _sample(t, dev_t, counter, yaw=0.0, lost=0):
    q = quat_from_euler_zyx(yaw, 0.0, 0.0)
    s = Sample(t, dev_t, "x", counter, q, np.array([0.0, 0, 1.0]), np.array([0, 0, 9.81]), np.zeros(3))
    if lost:
        s.extra["lost_before"] = lost
    return s


def test_clock_model_recovers_offset_and_drift_through_jitter():
    rng = np.random.default_rng(0)
    cm = ClockModel()
    drift, offset = 150e-6, 1234.5
    errs = []
    for k in range(3000):  # 30 s at 100 Hz
        true = 10.0 + k / 100
        dev_t = (true - 10.0) * (1 + drift) + offset
        arrival = true + 0.001 + rng.exponential(0.004)  # fixed 1 ms + jitter, never early
        st = cm.update(dev_t, arrival)
        if k > 1500:
            errs.append(st - (true + 0.001))
    errs = np.abs(errs)
    assert np.max(errs) < 0.001, np.max(errs)
    assert cm.slope == pytest.approx(1 / (1 + drift), abs=2e-5)


def test_clock_model_resets_when_device_restarts():
    cm = ClockModel()
    for k in range(100):
        cm.update(500 + k / 100, k / 100)
    cm.update(0.0, 1.01)  # device clock restarted after a reconnect
    assert cm.resets == 1 and cm.map(0.0) == pytest.approx(1.01)


def test_grid_hold_and_counter_gap_becomes_sensor_gap():
    hub = Hub({"pelvis": _dev("a"), "head": _dev("b")}, rate=60.0, latency=0.0, staleness=0.05, max_backlog=5)
    counter = 0
    for k in range(200):  # 2 s at 100 Hz
        t = 1.0 + k / 100
        if 100 <= k < 120:  # pelvis loses 20 packets (200 ms)
            counter += 1
            hub.push("head", _sample(t, None, k))
            continue
        hub.push("pelvis", _sample(t, None, counter & 0xFF, yaw=0.1 * k, lost=20 if k == 120 else 0))
        hub.push("head", _sample(t, None, k))
        counter += 1
    hub._next_index = 60  # start the grid at t = 1.0
    frames = hub.poll(now=3.0)
    assert len(frames) == 121  # grid points 1.0 .. 3.0 inclusive
    t = np.array([f.t for f in frames])
    pel = np.array([f.present[0] for f in frames])
    head = np.array([f.present[1] for f in frames])
    in_gap = (t > 1.995) & (t < 2.195)
    assert not pel[in_gap].any() and pel[(t < 1.98) | ((t > 2.21) & (t < 2.98))].all()
    assert head[t < 2.98].all()
    assert sum(sum(f.lost.values()) for f in frames) == 20
    f = frames[10]
    assert np.isnan(frames[int(np.argmax(in_gap))].quat[0]).all()
    assert np.allclose(np.linalg.norm(f.quat, axis=1), 1)


def test_bounded_queue_drops_oldest_and_counts():
    hub = Hub({"pelvis": _dev()}, queue_size=16)
    for k in range(100):
        hub.push("pelvis", _sample(k / 100, None, k))
    assert hub.stats.queued_dropped["pelvis"] == 84
    assert len(hub.tracks["pelvis"].queue) == 16


def test_slow_consumer_skips_backlog_instead_of_lagging():
    hub = Hub({"pelvis": _dev()}, latency=0.0, max_backlog=0.5)
    hub.push("pelvis", _sample(0.0, None, 0))
    hub.poll(now=0.0)
    frames = hub.poll(now=10.0)  # consumer was away for 10 s
    assert len(frames) == 30 and hub.stats.frames_skipped > 500
    assert frames[-1].t == pytest.approx(10.0)


def test_device_clock_used_for_session_time():
    hub = Hub({"pelvis": _dev()}, latency=0.0, staleness=0.02)
    rng = np.random.default_rng(1)
    for k in range(300):
        true = k / 100
        hub.push("pelvis", _sample(true + 0.002 + rng.exponential(0.01), 77.0 + true, k, yaw=true))
    hub._drain()
    ts = hub.tracks["pelvis"].ring.rows(-1)[:, 0]
    # arrival jitter (10 ms mean) is gone: session times are evenly spaced
    assert np.std(np.diff(ts[-100:])) < 1e-4


def test_injected_interpolation_interpolates():
    resample = pytest.importorskip("inference.signals.resample")
    hub = Hub(
        {"pelvis": _dev()},
        latency=0.0,
        staleness=0.05,
        max_backlog=5,
        interpolation=Interpolation(resample.slerp_unit, max_gap=0.05),
    )
    for k in range(100):
        hub.push("pelvis", _sample(k / 100, None, k, yaw=k / 100))  # yaw = t
    hub._next_index = 6
    frames = hub.poll(now=0.9)
    yaw = np.array([2 * np.arctan2(f.quat[0, 3], f.quat[0, 0]) for f in frames])
    t = np.array([f.t for f in frames])
    assert np.allclose(yaw, t, atol=1e-6)  # slerp between samples, not the held value


def test_hub_keeps_battery_and_status():
    """What a status panel shows of each device, the battery from the last sample that had one."""
    dev = drivers.make_device("xbus:///dev/imucap-no-such-port")  # never opened: the hub is fed by hand
    hub = Hub({"pelvis": dev})
    q = np.array([1.0, 0, 0, 0])
    hub.push("pelvis", Sample(t=1.0, device_time=1.0, device_id="p", quat=q, battery=80.0))
    hub.push("pelvis", Sample(t=1.01, device_time=1.01, device_id="p", quat=q))
    st = hub.status()["pelvis"]
    assert st["battery"] == 80.0 and st["packets"] == 0 and st["errors"] == 0 and st["gaps"] == 0
