"""Many devices at once, merged on one session clock and put on the 60 Hz grid.

Why each piece exists:

- One reader thread per device, so a slow or reconnecting device never delays
  another.
- Bounded queues between readers and the consumer: if the consumer (inference,
  GUI) falls behind, the oldest samples are dropped and counted, and grid frames
  older than ``max_backlog`` are skipped and counted, so the output always
  describes *now* instead of lagging further and further.
- A clock model per device (``ClockModel``): arrival times are jittered by the
  OS and the transport, device clocks are smooth but offset and drifting. A
  running linear fit of arrival time against device time, taken through the
  lower envelope of the arrivals (transport delay is never negative), gives
  jitter-free session times.
- Counter gaps become per-sensor gaps: grid points that fall between two
  samples with lost packets between them are marked missing, not held over.
- The grid: frames at k / rate on the session clock. The default is the latest
  sample held, missing when older than ``staleness``. The app injects
  inference's slerp resampler (``resampler=``) to interpolate instead; drivers
  cannot import it (layering), hence the callable.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from .base import Device, DeviceEvent, Sample

# (sample times (N,), quats (N,4), free acc (N,3), grid times (G,)) -> (quats (G,4), acc (G,3), valid (G,))
Resampler = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


class ClockModel:
    """session_time ~= offset + slope * device_time, refitted every ``refit`` samples
    over the last ``window`` pairs. Reset when the device clock jumps (a device
    restart after a reconnect)."""

    def __init__(self, window: int = 2048, refit: int = 32, jump: float = 1.0) -> None:
        self.window = window
        self.refit = refit
        self.jump = jump
        self._dev: deque[float] = deque(maxlen=window)
        self._arr: deque[float] = deque(maxlen=window)
        self.slope = 1.0
        self.offset: float | None = None
        self._since = 0
        self.resets = 0

    def update(self, device_t: float, arrival_t: float) -> float:
        if self.offset is not None:
            pred = self.offset + self.slope * device_t
            if abs(arrival_t - pred) > self.jump or (self._dev and device_t < self._dev[-1]):
                self.reset()
        self._dev.append(device_t)
        self._arr.append(arrival_t)
        self._since += 1
        if self.offset is None:
            self.offset = arrival_t - device_t
        elif self._since >= self.refit:
            self._fit()
        else:
            # keep the lower envelope current between fits
            self.offset = min(self.offset, arrival_t - self.slope * device_t)
        return self.map(device_t)

    def _fit(self) -> None:
        """Line through the per-chunk minima of (arrival - device time): those are the
        samples that met the least transport delay, so their scatter is small and
        their slope is the clock rate ratio."""
        self._since = 0
        d = np.fromiter(self._dev, float)
        a = np.fromiter(self._arr, float)
        if d.size >= 64 and d[-1] - d[0] > 1.0:
            chunk = max(8, d.size // 32)
            n = d.size // chunk * chunk
            r = (a[-n:] - d[-n:]).reshape(-1, chunk)
            j = np.argmin(r, axis=1) + np.arange(r.shape[0]) * chunk + (d.size - n)
            dm, am = d[j], a[j]
            dc = dm - dm.mean()
            den = float(np.dot(dc, dc))
            if den > 0:
                slope = float(np.dot(dc, am - am.mean()) / den)
                if 0.99 < slope < 1.01:  # a clock off by more than 1% is a broken fit, not drift
                    self.slope = slope
        self.offset = float(np.min(a - self.slope * d))

    def map(self, device_t: float) -> float:
        return (self.offset or 0.0) + self.slope * device_t

    def reset(self) -> None:
        self._dev.clear()
        self._arr.clear()
        self.offset = None
        self.slope = 1.0
        self._since = 0
        self.resets += 1


@dataclass
class HubFrame:
    """One grid frame. Arrays follow ``sites`` order; missing entries are NaN and
    ``present`` is False for them."""

    t: float
    index: int
    sites: tuple[str, ...]
    quat: np.ndarray
    free_acc: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    present: np.ndarray
    insole_force: np.ndarray
    contacts: np.ndarray
    insole_present: bool
    lost: dict[str, int] = field(default_factory=dict)


@dataclass
class HubStats:
    queued_dropped: dict[str, int] = field(default_factory=dict)
    frames: int = 0
    frames_skipped: int = 0
    gaps: dict[str, int] = field(default_factory=dict)


class _Ring:
    """Recent samples of one device as rows of a float array: t, quat(4), free_acc(3),
    acc(3), gyro(3); NaN where the device does not report a quantity. Rows are
    contiguous (the buffer is twice the capacity and slides back when full), so the
    grid code works on array views without per-sample Python."""

    COLS = 14

    def __init__(self, capacity: int = 512) -> None:
        self.cap = capacity
        self.buf = np.full((2 * capacity, self.COLS), np.nan)
        self.start = 0
        self.end = 0
        self.has = {"quat": False, "free_acc": False, "acc": False, "gyro": False}

    def __len__(self) -> int:
        return self.end - self.start

    def append(self, t: float, s: Sample) -> None:
        if self.end == self.buf.shape[0]:
            n = min(len(self), self.cap - 1)
            self.buf[:n] = self.buf[self.end - n : self.end]
            self.start, self.end = 0, n
        row = self.buf[self.end]
        row[:] = np.nan
        row[0] = t
        for name, sl in (
            ("quat", slice(1, 5)),
            ("free_acc", slice(5, 8)),
            ("acc", slice(8, 11)),
            ("gyro", slice(11, 14)),
        ):
            v = getattr(s, name)
            if v is not None:
                row[sl] = v
                self.has[name] = True
        self.end += 1
        if len(self) > self.cap:
            self.start = self.end - self.cap

    def rows(self, t_from: float) -> np.ndarray:
        """Rows with time >= t_from, plus the one before (the sample held at t_from)."""
        view = self.buf[self.start : self.end]
        i = int(np.searchsorted(view[:, 0], t_from, side="left"))
        return view[max(0, i - 1) :]

    def last_t(self) -> float | None:
        return float(self.buf[self.end - 1, 0]) if len(self) else None


class _Track:
    """Per-device state on the consumer side."""

    def __init__(self, name: str, device: Device, queue_size: int, history: int) -> None:
        self.name = name
        self.device = device
        self.queue: deque[Sample] = deque()
        self.queue_size = queue_size
        self.dropped = 0
        self.lock = threading.Lock()
        self.clock = ClockModel()
        self.ring = _Ring(history)
        self.insole: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=history)
        self.gap_spans: deque[tuple[float, float]] = deque(maxlen=64)
        self.lost_pending = 0
        self.thread: threading.Thread | None = None


class Hub:
    """Merge ``devices`` (name -> opened or unopened device) onto a ``rate`` Hz grid.

    Names are sensor sites; a device whose samples carry insole channels
    (``extra['force']``) feeds the insole part of the frame instead.
    """

    def __init__(
        self,
        devices: dict[str, Device],
        rate: float = 60.0,
        *,
        latency: float = 0.05,
        staleness: float = 0.05,
        queue_size: int = 256,
        max_backlog: float = 0.5,
        resampler: Resampler | None = None,
        clock: Callable[[], float] = time.monotonic,
        on_event: Callable[[DeviceEvent], None] | None = None,
        read_interval: float = 0.0,
    ) -> None:
        self.rate = rate
        self.read_interval = min(read_interval, latency / 2)
        self.latency = latency
        self.staleness = staleness
        self.max_backlog = max_backlog
        self.resampler = resampler
        self.clock = clock
        self.on_event = on_event
        self.tracks = {n: _Track(n, d, queue_size, history=512) for n, d in devices.items()}
        self.insole_names: set[str] = {n for n, d in devices.items() if d.kind == "insoles"}
        self.stats = HubStats()
        self._stop = threading.Event()
        self._next_index: int | None = None
        self.events: deque[DeviceEvent] = deque(maxlen=256)

    # --- threads ------------------------------------------------------------------------------------------
    def start(self) -> Hub:
        for tr in self.tracks.values():
            if not tr.device.is_open:
                tr.device.open()
            tr.thread = threading.Thread(target=self._reader, args=(tr,), name=f"hub-{tr.name}", daemon=True)
            tr.thread.start()
        return self

    def stop(self, close_devices: bool = True) -> None:
        self._stop.set()
        for tr in self.tracks.values():
            if tr.thread is not None:
                tr.thread.join(timeout=2.0)
            if close_devices:
                tr.device.close()

    def __enter__(self) -> Hub:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _reader(self, tr: _Track) -> None:
        dev = tr.device
        last_event = dev.events[-1] if dev.events else None
        while not self._stop.is_set():
            s = dev.read(0.1)
            if dev.events and dev.events[-1] is not last_event:  # forward connection events
                evs = list(dev.events)
                new = evs[evs.index(last_event) + 1 :] if last_event in evs else evs
                for ev in new:
                    self.events.append(ev)
                    if self.on_event:
                        self.on_event(ev)
                last_event = evs[-1]
            if s is not None:
                self.push(tr.name, s)
                if self.read_interval and not dev.has_buffered():
                    # batch: let a few packets accumulate instead of waking per packet
                    # (thread wake-ups dominate the cost at 13 x 100 Hz); bounded well below latency
                    self._stop.wait(self.read_interval)

    def push(self, name: str, s: Sample) -> None:
        """Enqueue a sample (reader threads call this; tests and replay may too)."""
        tr = self.tracks[name]
        with tr.lock:
            if len(tr.queue) >= tr.queue_size:
                tr.queue.popleft()
                tr.dropped += 1
                self.stats.queued_dropped[name] = tr.dropped
            tr.queue.append(s)

    # --- consumer side ------------------------------------------------------------------------------------
    def _drain(self) -> None:
        for tr in self.tracks.values():
            with tr.lock:
                batch = list(tr.queue)
                tr.queue.clear()
            for s in batch:
                st = tr.clock.update(s.device_time, s.t) if s.device_time is not None else s.t
                if "force" in s.extra:
                    self.insole_names.add(tr.name)
                lost = int(s.extra.get("lost_before", 0))
                last = tr.ring.last_t() if "force" not in s.extra else (tr.insole[-1][0] if tr.insole else None)
                if lost and last is not None:
                    tr.gap_spans.append((last, st))
                    tr.lost_pending += lost
                    self.stats.gaps[tr.name] = self.stats.gaps.get(tr.name, 0) + 1
                if last is not None and st <= last:
                    st = last + 1e-6  # keep per-device times strictly increasing
                if "force" in s.extra:
                    tr.insole.append(
                        (
                            st,
                            np.asarray(s.extra["force"], float),
                            np.asarray(s.extra.get("contacts", np.zeros(4, bool)), bool),
                        )
                    )
                else:
                    tr.ring.append(st, s)

    @property
    def sites(self) -> tuple[str, ...]:
        return tuple(n for n in self.tracks if n not in self.insole_names)

    def poll(self, now: float | None = None) -> list[HubFrame]:
        """All grid frames that are due (``now - latency``), oldest first."""
        self._drain()
        now = self.clock() if now is None else now
        horizon = now - self.latency
        last = math.floor(horizon * self.rate)
        if self._next_index is None:
            self._next_index = last
        first = self._next_index
        if last < first:
            return []
        max_frames = max(1, int(self.max_backlog * self.rate))
        if last - first + 1 > max_frames:
            self.stats.frames_skipped += last - first + 1 - max_frames
            first = last - max_frames + 1
        self._next_index = last + 1
        grid = np.arange(first, last + 1) / self.rate
        frames = self._frames(grid, first)
        self.stats.frames += len(frames)
        return frames

    def frames(self, duration: float | None = None) -> Iterator[HubFrame]:
        """Yield frames as they become due, for ``duration`` seconds (or until stopped)."""
        end = None if duration is None else self.clock() + duration
        while not self._stop.is_set() and (end is None or self.clock() < end):
            yield from self.poll()
            nxt = ((self._next_index or 0) / self.rate) + self.latency
            self._stop.wait(max(0.001, min(0.05, nxt - self.clock())))

    def _frames(self, grid: np.ndarray, first: int) -> list[HubFrame]:
        sites = self.sites
        G, S = grid.size, len(sites)
        quat = np.full((G, S, 4), np.nan)
        free = np.full((G, S, 3), np.nan)
        acc = np.full((G, S, 3), np.nan)
        gyro = np.full((G, S, 3), np.nan)
        present = np.zeros((G, S), bool)
        lost: dict[str, int] = {}
        for k, name in enumerate(sites):
            tr = self.tracks[name]
            if not len(tr.ring):
                continue
            if tr.lost_pending:
                lost[name] = tr.lost_pending
                tr.lost_pending = 0
            rows = tr.ring.rows(grid[0] - 0.5)
            ts = rows[:, 0]
            idx = np.searchsorted(ts, grid, side="right") - 1
            ii = np.maximum(idx, 0)
            ok = (idx >= 0) & (grid - ts[ii] <= self.staleness)
            for a, b in tr.gap_spans:
                ok &= ~((grid > a) & (grid < b))
            if self.resampler is not None and tr.ring.has["quat"]:
                if ts.size >= 2:
                    fa = rows[:, 5:8] if tr.ring.has["free_acc"] else np.zeros((ts.size, 3))
                    q_g, a_g, v_g = self.resampler(ts, rows[:, 1:5], fa, grid)
                    ok &= np.asarray(v_g, bool)
                    quat[:, k] = q_g
                    if tr.ring.has["free_acc"]:
                        free[:, k] = a_g
                else:
                    ok[:] = False
            else:
                quat[:, k] = rows[ii, 1:5]
                free[:, k] = rows[ii, 5:8]
            acc[:, k] = rows[ii, 8:11]
            gyro[:, k] = rows[ii, 11:14]
            present[:, k] = ok
        for arr in (quat, free, acc, gyro):
            arr[~present] = np.nan
        force = np.full((G, 2), np.nan)
        contacts = np.zeros((G, 4), bool)
        ins_ok = np.zeros(G, bool)
        for name in self.insole_names:
            tr = self.tracks[name]
            if not tr.insole:
                continue
            ts = np.fromiter((h[0] for h in tr.insole), float, len(tr.insole))
            idx = np.searchsorted(ts, grid, side="right") - 1
            ok = (idx >= 0) & (grid - ts[np.maximum(idx, 0)] <= self.staleness)
            for g in np.nonzero(ok)[0]:
                _, f, c = tr.insole[idx[g]]
                force[g] = f
                contacts[g] = c
            ins_ok |= ok
        self._trim()
        return [
            HubFrame(
                float(grid[g]),
                first + g,
                sites,
                quat[g],
                free[g],
                acc[g],
                gyro[g],
                present[g],
                force[g],
                contacts[g],
                bool(ins_ok[g]),
                lost if g == 0 else {},
            )
            for g in range(G)
        ]

    def _trim(self) -> None:
        """Forget gap spans that are older than anything a future frame can ask for."""
        if self._next_index is None:
            return
        t_min = self._next_index / self.rate - 1.0
        for tr in self.tracks.values():
            while tr.gap_spans and tr.gap_spans[0][1] < t_min:
                tr.gap_spans.popleft()


def resampler_from_to_grid(to_grid: Callable[..., tuple], fps: float = 60.0, max_gap: float = 0.1) -> Resampler:
    """Adapt ``inference.resample.to_grid(t, quat, acc, fps, max_gap, t0)`` to the hub's
    ``Resampler`` signature (the app does this; drivers cannot import inference)."""

    def resample(t: np.ndarray, q: np.ndarray, a: np.ndarray, grid: np.ndarray):
        tg, qg, ag, valid = to_grid(t, q, a, fps=fps, max_gap=max_gap, t0=float(grid[0]))
        G = grid.size
        quat = np.full((G, 4), np.nan)
        acc = np.full((G, 3), np.nan)
        ok = np.zeros(G, bool)
        n = min(G, len(tg))
        quat[:n], acc[:n], ok[:n] = qg[:n], ag[:n], valid[:n]
        return quat, acc, ok

    return resample
