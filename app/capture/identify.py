"""Which of the connected sensors is the one in the person's hand?

Serial ports are numbered by plug order, CAN ids by a sticker, and a DualSense looks like
any other: the only reliable way to know which device is which is to move one and watch.
The watcher turns each device's stream into an angular speed, smoothed over a fraction of
a second, and names a device only when it clearly leads all others, so a sensor bumped
while strapping another on does not get the wrong name.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from drivers.base import Sample

STALE_AFTER_S = 0.5  # a device silent this long is treated as still (unplugged, out of range)
GAP_RESET_S = 1.0  # a jump in device time this long (or backwards) starts the window afresh


class _Track:
    """One device's recent motion: gyro magnitudes when the device measures rotation rate,
    else its orientations, within the smoothing window."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.rates: deque[tuple[float, float]] = deque()  # (time, deg/s) from the gyro
        self.quats: deque[tuple[float, np.ndarray]] = deque()  # (time, quaternion)
        self.arrival: float | None = None  # session time of the latest sample

    def push(self, s: Sample) -> None:
        self.arrival = s.t if self.arrival is None else max(self.arrival, s.t)
        t = s.device_time if s.device_time is not None else s.t
        last = self._last_time()
        if last is not None and (t < last or t - last > GAP_RESET_S):
            self.rates.clear()
            self.quats.clear()
        if s.gyro is not None:
            self.rates.append((t, math.degrees(float(np.linalg.norm(s.gyro)))))
        elif s.quat is not None:
            self.quats.append((t, np.asarray(s.quat, dtype=float)))
        self._trim(t)

    def _last_time(self) -> float | None:
        times = [d[-1][0] for d in (self.rates, self.quats) if d]
        return max(times) if times else None

    def _trim(self, now: float) -> None:
        for d in (self.rates, self.quats):
            while d and d[0][0] < now - self.window_s:
                d.popleft()

    def speed(self) -> float:
        if self.rates:
            return float(np.mean([r for _, r in self.rates]))
        return self._quat_speed()

    def _quat_speed(self) -> float:
        """Rotation travelled over the window from orientations a third of a window apart:
        consecutive samples 10 ms apart would add up their noise into a speed of its own."""
        if len(self.quats) < 2:
            return 0.0
        step = self.window_s / 3
        anchors = [self.quats[0]]
        for item in list(self.quats)[1:]:
            if item[0] - anchors[-1][0] >= step:
                anchors.append(item)
        if anchors[-1] is not self.quats[-1]:
            anchors.append(self.quats[-1])
        span = anchors[-1][0] - anchors[0][0]
        if span <= 0:
            return 0.0
        angle = sum(_angle_deg(a[1], b[1]) for a, b in zip(anchors, anchors[1:]))
        return angle / span


def _angle_deg(q0: np.ndarray, q1: np.ndarray) -> float:
    d = abs(float(np.dot(q0, q1))) / max(1e-12, float(np.linalg.norm(q0) * np.linalg.norm(q1)))
    return math.degrees(2.0 * math.acos(min(1.0, d)))


class MotionWatcher:
    """Says which device is being moved. Thread-safe: reader threads push, a UI asks.

    ``lead``: how many times faster than the runner-up the winner must turn, so that two
    sensors on the same moving arm, or a bump, name nobody. ``clock``: the clock sample
    ``t`` stamps come from (the drivers' ``time.monotonic``); with it a device that went
    silent counts as still; without it, silence is judged against the newest sample.
    """

    def __init__(
        self,
        keys: Iterable[str],
        threshold_dps: float = 60.0,
        window_s: float = 0.3,
        *,
        lead: float = 2.0,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.threshold_dps = threshold_dps
        self.window_s = window_s
        self.lead = lead
        self.clock = clock
        self._tracks = {k: _Track(window_s) for k in keys}
        self._lock = threading.Lock()

    def push(self, key: str, sample: Sample) -> None:
        with self._lock:
            track = self._tracks.get(key)
            if track is None:
                track = self._tracks[key] = _Track(self.window_s)
            track.push(sample)

    def speeds(self) -> dict[str, float]:
        """Angular speed of each device, deg/s, smoothed over the window."""
        with self._lock:
            arrivals = [t.arrival for t in self._tracks.values() if t.arrival is not None]
            now = self.clock() if self.clock is not None else max(arrivals, default=0.0)
            return {k: (0.0 if t.arrival is None or now - t.arrival > STALE_AFTER_S else t.speed())
                    for k, t in self._tracks.items()}

    def moving(self, among: Iterable[str] | None = None) -> str | None:
        """The device clearly being moved now (optionally only among ``among``), else None."""
        speeds = self.speeds()
        if among is not None:
            wanted = set(among)
            speeds = {k: v for k, v in speeds.items() if k in wanted}
        ranked = sorted(speeds.items(), key=lambda kv: kv[1], reverse=True)
        if not ranked or ranked[0][1] < self.threshold_dps:
            return None
        runner_up = ranked[1][1] if len(ranked) > 1 else 0.0
        return ranked[0][0] if ranked[0][1] >= self.lead * runner_up else None


class DeviceReaders:
    """Opens devices in parallel, one thread each, and feeds every sample to a watcher.

    Why a thread per device and a parallel open: an Xsens MTi takes up to seconds to
    acknowledge its configuration, and a device that is not there fails only after its
    timeout; opened one after another, ten sensors would keep the person waiting.
    """

    def __init__(self, urls: Sequence[str], watcher: MotionWatcher,
                 on_error: Callable[[str, str], None] | None = None) -> None:
        self.urls = list(urls)
        self.watcher = watcher
        self.on_error = on_error
        self.opened: set[str] = set()
        self.failed: dict[str, str] = {}
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._settled = threading.Semaphore(0)
        self._lock = threading.Lock()

    def start(self) -> DeviceReaders:
        for url in self.urls:
            th = threading.Thread(target=self._run, args=(url,), name=f"identify-{url}", daemon=True)
            th.start()
            self._threads.append(th)
        return self

    def wait_opened(self, timeout: float | None = None) -> None:
        """Until every device has opened or failed (or ``timeout``)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        for _ in self.urls:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not self._settled.acquire(timeout=left):
                return

    def all_failed(self) -> bool:
        with self._lock:
            return len(self.failed) == len(self.urls)

    def stop(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(timeout=5.0)
        self._threads.clear()

    def __enter__(self) -> DeviceReaders:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self, url: str) -> None:
        import drivers

        try:
            dev = drivers.open_device(url)
        except (OSError, ValueError) as exc:
            with self._lock:
                self.failed[url] = " ".join(str(exc).split()) or type(exc).__name__
            self._settled.release()
            if self.on_error is not None:
                self.on_error(url, self.failed[url])
            return
        with self._lock:
            self.opened.add(url)
        self._settled.release()
        try:
            while not self._stop.is_set():
                for s in dev.read_many(0.1):
                    self.watcher.push(url, s)
        except (OSError, ValueError) as exc:  # reconnect=0 in the URL: the loss ends this device
            with self._lock:
                self.failed[url] = " ".join(str(exc).split())
            if self.on_error is not None:
                self.on_error(url, self.failed[url])
        finally:
            dev.close()


def watch_devices(
    urls: Sequence[str],
    seconds: float,
    on_update: Callable[[dict[str, float], str | None], None] | None = None,
    *,
    threshold_dps: float = 60.0,
    interval: float = 0.1,
    on_error: Callable[[str, str], None] | None = None,
) -> str | None:
    """Listen to ``urls`` for ``seconds``, calling ``on_update(speeds, winner)`` every
    ``interval``; return the last device found moving (None if none was). Raises OSError
    when not one of the devices could be opened."""
    watcher = MotionWatcher(urls, threshold_dps, clock=time.monotonic)
    last: str | None = None
    with DeviceReaders(urls, watcher, on_error) as readers:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not readers.all_failed():
            time.sleep(min(interval, max(0.0, end - time.monotonic())))
            winner = watcher.moving()
            last = winner or last
            if on_update is not None:
                on_update(watcher.speeds(), winner)
        if readers.all_failed():
            reasons = "; ".join(f"{u}: {why}" for u, why in readers.failed.items())
            raise OSError(f"no device could be opened ({reasons})")
    return last
