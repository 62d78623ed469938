"""Hub on a busy machine: samples that reach it after their frame's time has passed.

One device delivers on time, the other in bursts every 150 ms (its reader got no core in
between), each sample stamped with the time it was taken. With a fixed wait the late
device is missing from most frames; with ``max_latency`` the grid falls behind just enough
and the frames are whole, then the wait comes back once the bursts stop. Deterministic: a
simulated clock, the hub polled every 60th of a second."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers._math import quat_from_euler_zyx
from drivers.base import Sample
from drivers.hub import LATE_PERSIST_S, LATE_QUIET_S, Hub, Interpolation

resample = pytest.importorskip("inference.signals.resample")


def _sample(t: float) -> Sample:
    q = quat_from_euler_zyx(t, 0.0, 0.0)
    return Sample(t, None, "x", int(t * 100) & 0xFF, q, np.zeros(3), np.array([0, 0, 9.81]), np.zeros(3))


def _run(max_latency: float | None, burst_until: float = 12.0, seconds: float = 40.0, stalls=None):
    """``stalls``: (start, seconds) spans in which b's samples are held, instead of the
    bursts every 150 ms until ``burst_until``."""
    now = [0.0]
    devs = {n: drivers.make_device(f"bno08x-rvc:///dev/null-late-{n}") for n in ("a", "b")}
    hub = Hub(devs, latency=0.05, max_backlog=2.0, queue_size=4096, clock=lambda: now[0],
              interpolation=Interpolation(resample.slerp_unit), max_latency=max_latency)
    frames, waits = [], []
    held: list[Sample] = []
    k = 0
    for step in range(int(seconds * 600)):  # 0.6 kHz simulation ticks
        now[0] = 1.0 + step / 600
        while 1.0 + k / 100 <= now[0]:  # both devices take a sample at 100 Hz
            t = 1.0 + k / 100
            hub.push("a", _sample(t))
            held.append(_sample(t))
            k += 1
        if stalls is not None:
            release = not any(a <= now[0] < a + d for a, d in stalls)
        else:
            release = now[0] >= burst_until or step % 90 == 0  # b's samples wait up to 150 ms for a burst
        if release:
            for s in held:
                hub.push("b", s)
            held.clear()
        if step % 10 == 0:
            for f in hub.poll():
                frames.append((f.t, bool(f.present[1])))
            waits.append((now[0], hub.latency))
    t = np.array([f[0] for f in frames])
    present_b = np.array([f[1] for f in frames])
    return hub, t, present_b, np.array(waits)


def test_a_fixed_wait_loses_the_late_device_from_frames():
    hub, t, present_b, _ = _run(None)
    during = (t > 3.0) & (t < 11.0)
    assert present_b[during].mean() < 0.7
    assert hub.stats.late > 0 and hub.stats.latency_raised == 0


def test_the_wait_grows_for_late_samples_and_comes_back():
    hub, t, present_b, waits = _run(0.25)
    during = (t > 3.0) & (t < 11.0)
    assert present_b[during].mean() > 0.99
    assert 0.14 < hub.stats.latency_max <= 0.25  # the oldest sample of a burst: 140 ms, + 10 ms
    assert present_b[t > 12.0].mean() > 0.99
    w_late = waits[(waits[:, 0] > 5) & (waits[:, 0] < 12), 1]
    assert w_late.min() > 0.14  # held while samples keep coming late
    end = waits[-1, 1]
    assert end == pytest.approx(0.05)  # 10 s quiet, then 5 ms a second: back well before 41 s
    # never two frames for one grid time, none skipped, in order
    assert np.all(np.diff(t) > 0) and np.allclose(np.diff(t), 1 / 60)


def test_the_wait_is_capped():
    hub, t, present_b, _ = _run(0.1)
    assert hub.stats.latency_max == pytest.approx(0.1)
    assert LATE_QUIET_S > 0


def test_one_stall_is_not_waited_for():
    """A single 200 ms stall (the whole process missed its core once) loses b from the
    frames it covers whatever the hub does next; growing the wait for it would only put
    200 ms on every later frame."""
    hub, t, present_b, waits = _run(0.25, seconds=20.0, stalls=[(5.0, 0.2)])
    assert hub.stats.late > 0 and hub.stats.latency_raised == 0
    assert np.all(waits[:, 1] == pytest.approx(0.05))
    assert present_b[t > 6.0].all()


def test_stalls_that_come_back_are_waited_for():
    """The same stall again 3 s later is a machine that keeps missing its core: the wait
    grows to cover it, and the third stall's samples reach their frames."""
    hub, t, present_b, waits = _run(0.25, seconds=30.0, stalls=[(5.0, 0.2), (8.0, 0.2), (11.0, 0.2)])
    assert 3.0 > LATE_PERSIST_S
    assert hub.stats.latency_raised >= 1 and 0.2 <= hub.stats.latency_max <= 0.25
    third = (t > 10.9) & (t < 11.3)
    assert present_b[third].all()
    assert not present_b[(t > 7.9) & (t < 8.2)].all()  # the second came before the wait grew
