"""Hub under clock trouble: a device clock that jumps, runs fast or slow, or restarts from
zero mid-stream must stay aligned with the others within one 60 Hz frame once a short
transition is over.

Deterministic: every sample is a real ``Sample`` pushed through ``Hub.push_many`` in the
batches a reader thread would deliver, stamped with a simulated arrival clock (transport
delay plus one-sided jitter), and the hub polls on that clock; no real time passes. Each
sample carries its true capture time in ``free_acc[0]``, so a grid frame tells which
instant each stream is showing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

import drivers
from drivers.base import CounterTracker, Sample
from drivers.hub import ClockModel, Hub

FRAME = 1 / 60
RATE = 100.0  # samples per second per device
DURATION = 30.0
FAULT_AT = 20.0
TRANSITION = 1.0  # s after the fault (or after the start) that need not be aligned


@dataclass
class Stream:
    """One simulated device: ``device_time(true)`` is its clock; its samples are taken
    every 1 / ``rate`` s of true time."""

    name: str
    device_time: Callable[[np.ndarray], np.ndarray]
    rate: float = RATE
    restart_at: float | None = None  # the packet counter starts from zero again here


def _device() -> drivers.Device:
    return drivers.make_device("bno08x-rvc:///dev/null-clock")


def _simulate(streams: list[Stream], *, seed: int = 0, duration: float = DURATION, batch: float = 0.01,
              delay: float = 0.002, jitter: float = 0.004, hub_kw: dict | None = None) -> tuple[np.ndarray, dict]:
    """Run the streams through a hub; (grid times, {name: true time shown at each grid time}),
    NaN where a stream was marked missing."""
    rng = np.random.default_rng(seed)
    now = [0.0]
    hub = Hub({s.name: _device() for s in streams}, rate=60.0, clock=lambda: now[0], **(hub_kw or {}))
    pending: list[tuple[float, str, Sample]] = []
    for k, s in enumerate(streams):
        true = np.arange(0.0, duration, 1 / s.rate) + 0.0013 * k  # devices are not in phase
        # a transport delivers in order: a delayed sample holds up the ones behind it
        arrival = np.maximum.accumulate(true + delay + rng.exponential(jitter, true.size))
        dev_t = s.device_time(true)
        count = np.arange(true.size)
        if s.restart_at is not None:
            count = np.where(true >= s.restart_at, count - int(np.searchsorted(true, s.restart_at)), count)
        tracker = CounterTracker(256)  # what the device base turns the wire counter into
        for tt, at, dt, c in zip(true, arrival, dev_t, count, strict=True):
            smp = Sample(float(at), float(dt), s.name, int(c) & 0xFF, np.array([1.0, 0, 0, 0]),
                         np.array([tt, 0.0, 0.0]), np.array([0, 0, 9.81]), np.zeros(3))
            lost = tracker.update(smp.counter)
            if lost:
                smp.extra["lost_before"] = lost
            pending.append((float(at), s.name, smp))
    pending.sort(key=lambda x: x[0])
    grid_t: list[float] = []
    shown: dict[str, list[float]] = {s.name: [] for s in streams}
    j = 0
    for step in np.arange(batch, duration, batch):
        now[0] = float(step)
        batches: dict[str, list[Sample]] = {}
        while j < len(pending) and pending[j][0] <= step:
            batches.setdefault(pending[j][1], []).append(pending[j][2])
            j += 1
        for name, b in batches.items():
            hub.push_many(name, b)
        for f in hub.poll():
            grid_t.append(f.t)
            for k, name in enumerate(f.sites):
                shown[name].append(float(f.free_acc[k][0]) if f.present[k] else np.nan)
    return np.array(grid_t), {k: np.array(v) for k, v in shown.items()}


def _misalignment(t: np.ndarray, shown: dict, a: str, b: str, skip: list[tuple[float, float]]) -> np.ndarray:
    """|true time shown by a - true time shown by b| on grid frames outside the ``skip`` spans."""
    ok = np.ones(t.size, bool)
    for lo, hi in skip:
        ok &= ~((t >= lo) & (t < hi))
    return np.abs(shown[a][ok] - shown[b][ok])


def _good(true: np.ndarray) -> np.ndarray:
    return 1000.0 + true * (1 + 20e-6)  # an ordinary crystal: offset and 20 ppm


def _check(streams: list[Stream], skip: list[tuple[float, float]], **kw) -> tuple[np.ndarray, dict]:
    t, shown = _simulate(streams, **kw)
    skip = [(0.0, TRANSITION), *skip]
    err = _misalignment(t, shown, "ref", "dev", skip)
    assert np.isfinite(err).mean() > 0.98, f"present only {np.isfinite(err).mean():.3f} of the time"
    err = err[np.isfinite(err)]
    assert err.max() <= FRAME, f"misaligned by up to {err.max() * 1e3:.1f} ms (p99 {np.percentile(err, 99) * 1e3:.1f})"
    return t, shown


def _jumped(step: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda true: _good(true) + np.where(true >= FAULT_AT, step, 0.0)


@pytest.mark.parametrize("step", [5.0, -3.0, 0.5, -0.5, 0.05, -0.05, 0.012])
def test_clock_jump_realigns_within_a_frame(step):
    _check([Stream("ref", _good), Stream("dev", _jumped(step))], [(FAULT_AT, FAULT_AT + TRANSITION)])


@pytest.mark.parametrize("rate_error", [0.01, -0.01, 0.03, -0.03])
def test_clock_running_fast_or_slow_stays_aligned(rate_error):
    """A clock off by a percent or more (an oscillator out of spec, or a device whose time
    is its packet counter over a nominal rate it does not keep)."""
    _check([Stream("ref", _good), Stream("dev", lambda true: 50.0 + true * (1 + rate_error))], [])


@pytest.mark.parametrize("rate_error", [0.0, 0.01, -0.01])
def test_clock_restarting_from_zero_mid_stream_realigns(rate_error):
    """A device that reboots (brown-out, reconnect) starts its clock and its packet counter
    at zero again while the others keep going."""

    def dev_time(true: np.ndarray) -> np.ndarray:
        before = 7.5 + true * (1 + rate_error)
        return np.where(true >= FAULT_AT, (true - FAULT_AT) * (1 + rate_error), before)

    _check([Stream("ref", _good), Stream("dev", dev_time, restart_at=FAULT_AT)], [(FAULT_AT, FAULT_AT + TRANSITION)])


def test_repeated_restarts_and_jumps_with_heavy_jitter():
    """Several faults in one session, with 15 ms of mean jitter on the transport (a
    Bluetooth link): the hub is given the latency such a link needs, else samples miss
    their frame whatever the clock does."""

    def dev_time(true: np.ndarray) -> np.ndarray:
        out = 3.0 + true * 1.01
        out = np.where(true >= 10.0, (true - 10.0) * 1.01, out)  # restart
        out = np.where(true >= 18.0, out + 4.0, out)  # jump forward
        return np.where(true >= 27.0, out - 2.0, out)  # jump back

    skip = [(a, a + TRANSITION) for a in (10.0, 18.0, 27.0)]
    _check([Stream("ref", _good), Stream("dev", dev_time, restart_at=10.0)], skip, jitter=0.015, seed=3,
           hub_kw={"latency": 0.15})


def test_clock_model_keeps_the_rate_across_a_restart():
    """A reboot resets the clock's zero, not its oscillator: the fitted rate survives it."""
    cm = ClockModel()
    for k in range(1500):
        cm.update(k / 100 * 1.02, k / 100)
    slope = cm.slope
    assert slope == pytest.approx(1 / 1.02, rel=1e-3)
    cm.update(0.0, 15.0)
    assert cm.resets == 1 and cm.slope == slope
