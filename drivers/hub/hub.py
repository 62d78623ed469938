"""Many devices at once, merged on one session clock and put on the 60 Hz grid.

Why each piece exists:

- Readers: one selector thread serves every device with a file descriptor
  (serial ports, UDP): it wakes once per ``read_interval``, not once per packet,
  and drains each ready device with ``read_many``, so 13 sensors at 100 Hz cost
  ~100 wake-ups a second instead of 1300. Queue-backed transports (python-can's
  virtual bus, the HID seam) keep a thread of their own, and a selectable device
  gets one while it reconnects, so a slow handshake never delays the others.
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
  samples with lost packets between them are marked missing, not held over;
  with a resampler, a gap no longer than ``fill_gap`` is interpolated across
  instead (below).
- The grid: frames at k / rate on the session clock. The default is the latest
  sample held, missing when older than ``staleness``. The app injects
  inference's slerp resampler (``resampler=``) to interpolate instead; drivers
  cannot import it (layering), hence the callable.
- ``latency``: how far behind now the grid runs. Interpolating needs the sample
  *after* a grid time, so it waits for the next sample of every site; holding
  only needs the sample at or before it to have been read, a few milliseconds
  (the low-latency mode, docs/latency.md).
- Each frame says which sample of each site went into it last (``sample_t``,
  ``sample_counter``), so a latency measurement starts at a real sample.
- ``max_latency``: on a busy machine the readers or the consumer miss their core for
  tens of milliseconds, samples reach the hub after their frame has gone out, and that
  site is missing from the frame, and from the recording, which stores the frames. With
  ``max_latency`` set the grid falls further behind instead, just enough for the late
  samples seen (up to ``max_latency``), and creeps back to ``latency`` once none has
  been late for ``LATE_QUIET_S``. It grows only when lateness lasts or comes back (late
  samples ``LATE_PERSIST_S`` apart with no quiet spell between): a single stall of the
  whole process (the garbage collector, the window's first draw of a view) loses its
  samples' frames whatever the wait does afterwards, so answering it would only add that
  stall to every frame's latency for the next minute (the window's live loop ran 220-270
  ms behind instead of ~70 ms).
"""

from __future__ import annotations

import math
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from .base import Device, DeviceEvent, Sample

# (sample times (N,), quats (N,4), free acc (N,3), grid times (G,)) -> (quats (G,4), acc (G,3), valid (G,))
Resampler = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


class ClockModel:
    """session_time ~= offset + slope * device_time, refitted every ``refit`` samples
    over the last ``window`` pairs.

    Reset (the pairs forgotten, the fitted rate kept: a reboot moves a clock's zero, not
    its oscillator) when the device clock jumps: backwards at all (a restart from zero
    after a brown-out or reconnect), forwards by more than ``ahead`` (a sample cannot
    arrive before it was sent, so an arrival that much earlier than predicted means the
    device time leapt), or by more than ``jump`` either way. Without the forward check a
    leap of 50 ms .. 1 s was absorbed by the lower envelope and then bent the next fit,
    whose window straddled it: streams stayed ~50 ms apart for the whole window."""

    def __init__(self, window: int = 2048, refit: int = 32, jump: float = 1.0, ahead: float = 0.005,
                 max_rate_error: float = 0.05) -> None:
        self.window = window
        self.refit = refit
        self.jump = jump
        self.ahead = ahead
        self.max_rate_error = max_rate_error
        self._dev: deque[float] = deque(maxlen=window)
        self._arr: deque[float] = deque(maxlen=window)
        self.slope = 1.0
        self.offset: float | None = None
        self._since = 0
        self._floor_d: float | None = None  # device time of the last sample on the envelope
        self.resets = 0

    def update(self, device_t: float, arrival_t: float) -> float:
        if self.offset is not None:
            resid = arrival_t - (self.offset + self.slope * device_t)
            # a slope that is off lets the prediction run ahead of the arrivals by up to
            # max_rate_error per second since a sample last sat on the envelope: not a jump
            early = self.ahead + self.max_rate_error * (device_t - (self._floor_d or device_t))
            if resid < -early or abs(resid) > self.jump or (self._dev and device_t < self._dev[-1]):
                self.reset()
            elif resid <= self.ahead:
                self._floor_d = device_t
        self._dev.append(device_t)
        self._arr.append(arrival_t)
        self._since += 1
        if self.offset is None:
            self.offset = arrival_t - self.slope * device_t
            self._floor_d = device_t
        elif self._since >= (self.refit if len(self._dev) < 256 else 4 * self.refit):
            # once the window holds seconds of data the slope hardly moves between fits;
            # fitting 4x less often saves most of the hub's numpy time at 13 x 100 Hz
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
        # half a second of pairs already pins a clock that is off by percents far better
        # than the nominal rate does (a 3 % slow clock drifts 15 ms in that time)
        if d.size >= 32 and d[-1] - d[0] > 0.5:
            chunk = max(8, d.size // 32)
            n = d.size // chunk * chunk
            r = (a[-n:] - d[-n:]).reshape(-1, chunk)
            j = np.argmin(r, axis=1) + np.arange(r.shape[0]) * chunk + (d.size - n)
            dm, am = d[j], a[j]
            dc = dm - dm.mean()
            den = float(np.dot(dc, dc))
            if den > 0:
                slope = float(np.dot(dc, am - am.mean()) / den)
                # a device clock can be off by percents (a BNO08x's time is its counter over a
                # nominal 100 Hz its oscillator does not quite keep); beyond a few it is a broken fit
                if abs(slope - 1.0) < self.max_rate_error:
                    self.slope = slope
        self.offset = float(np.min(a - self.slope * d))

    def map(self, device_t: float) -> float:
        return (self.offset or 0.0) + self.slope * device_t

    def reset(self) -> None:
        """Forget the pairs and the offset; keep the fitted rate (same oscillator)."""
        self._dev.clear()
        self._arr.clear()
        self.offset = None
        self._floor_d = None
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
    # per site: session time and wire packet counter of the newest sample that went into
    # this frame (NaN where none did or the device sends no counter); None from sources
    # that are not a hub (synthetic frames, recordings)
    sample_t: np.ndarray | None = None
    sample_counter: np.ndarray | None = None


@dataclass
class HubStats:
    queued_dropped: dict[str, int] = field(default_factory=dict)
    frames: int = 0
    frames_skipped: int = 0
    gaps: dict[str, int] = field(default_factory=dict)
    late: int = 0  # samples that reached the hub later than the grid's wait at the time
    latency_raised: int = 0  # times the wait grew for them (``max_latency``)
    latency_max: float = 0.0  # the longest wait used


LATE_QUIET_S = 10.0  # s without a late sample before the grid's wait comes back down
LATENCY_RELAX = 0.005  # s of wait given back per s after that
LATE_MARGIN = 0.01  # s of wait beyond the latest sample seen late
LATE_PERSIST_S = 1.0  # s that late samples must keep coming (or come back) before the wait grows


class _Ring:
    """Recent samples of one device as rows of a float array: t, quat(4), free_acc(3),
    acc(3), gyro(3), packet counter; NaN where the device does not report a quantity. Rows are
    contiguous (the buffer is twice the capacity and slides back when full), so the
    grid code works on array views without per-sample Python."""

    COLS = 15
    COUNTER = 14

    def __init__(self, capacity: int = 512) -> None:
        self.cap = capacity
        self.buf = np.full((2 * capacity, self.COLS), np.nan)
        self.start = 0
        self.end = 0
        self.has = {"quat": False, "free_acc": False, "acc": False, "gyro": False}

    def __len__(self) -> int:
        return self.end - self.start

    _FIELDS = (("quat", 1, 5), ("free_acc", 5, 8), ("acc", 8, 11), ("gyro", 11, 14))

    def append(self, t: float, s: Sample) -> None:
        self.extend([t], [s])

    def extend(self, ts: list[float], samples: list[Sample]) -> None:
        """Write a batch of samples as rows, one numpy assignment per quantity."""
        n = len(samples)
        if n > self.cap:
            ts, samples, n = ts[-self.cap :], samples[-self.cap :], self.cap
        if self.end + n > self.buf.shape[0]:
            keep = min(len(self), self.cap - n)
            self.buf[:keep] = self.buf[self.end - keep : self.end]
            self.start, self.end = 0, keep
        block = self.buf[self.end : self.end + n]
        block[:, 0] = ts
        block[:, self.COUNTER] = [np.nan if s.counter is None else s.counter for s in samples]
        for name, a, b in self._FIELDS:
            vals = [getattr(s, name) for s in samples]
            if all(v is not None for v in vals):
                block[:, a:b] = vals
                self.has[name] = True
            else:
                for r, v in zip(block, vals, strict=True):
                    if v is None:
                        r[a:b] = np.nan
                    else:
                        r[a:b] = v
                        self.has[name] = True
        self.end += n
        if len(self) > self.cap:
            self.start = self.end - self.cap

    def rows(self, t_from: float) -> np.ndarray:
        """Rows with time >= t_from, plus the one before (the sample held at t_from)."""
        view = self.buf[self.start : self.end]
        i = int(np.searchsorted(view[:, 0], t_from, side="left"))
        return view[max(0, i - 1) :]

    def last(self, n: int) -> np.ndarray:
        """The newest ``n`` rows, NaN-padded at the front when fewer are held."""
        if len(self) >= n:
            return self.buf[self.end - n : self.end]
        out = np.full((n, self.COLS), np.nan)
        if len(self):
            out[n - len(self) :] = self.buf[self.start : self.end]
        return out

    def last_t(self) -> float | None:
        return float(self.buf[self.end - 1, 0]) if len(self) else None


class _Track:
    """Per-device state on the consumer side."""

    def __init__(self, name: str, device: Device, queue_size: int, history: int) -> None:
        self.name = name
        self.device = device
        self.queue: deque[Sample] = deque(maxlen=queue_size)
        self.queue_size = queue_size
        self.dropped = 0
        self.lock = threading.Lock()
        self.clock = ClockModel()
        self.ring = _Ring(history)
        self.insole: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=history)
        self.gap_spans: deque[tuple[float, float]] = deque(maxlen=64)
        self.lost_pending = 0
        self.thread: threading.Thread | None = None
        self.last_event: DeviceEvent | None = device.events[-1] if device.events else None


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
        read_interval: float | None = None,
        selector: bool = True,
        fill_gap: float = 0.1,
        max_latency: float | None = None,
    ) -> None:
        self.rate = rate
        # Radio loss comes in bursts of a few packets. Marking every grid point inside such a
        # burst missing cost the reconstruction a site's observation in ~30 % of frames at 20 %
        # loss (docs/robustness.md), where interpolating across 30-100 ms of human motion errs
        # far less than the poser guessing the site; so with a resampler, gaps up to
        # ``fill_gap`` s are bridged.
        self.fill_gap = fill_gap
        # the selector's sleep between drains; default one grid period: a sample waits at
        # most one frame before it is queued, well inside ``latency`` (13 x 100 Hz: 0.10 of a
        # core at 10 ms, 0.08 at 16.7 ms, docs/devices.md)
        self.read_interval = min(1.0 / rate if read_interval is None else read_interval, latency / 2)
        self.selector = selector
        self._selector_thread: threading.Thread | None = None
        self.latency = latency
        self.base_latency = latency
        self.max_latency = max_latency if max_latency is None else max(max_latency, latency)
        self._last_late: float | None = None
        self._late_since: float | None = None  # when the current spell of late samples began
        self._late_worst = 0.0  # the oldest sample of that spell
        self._last_poll: float | None = None
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
        selectable: list[_Track] = []
        for tr in self.tracks.values():
            if not tr.device.is_open:
                tr.device.open()
            if self.selector and tr.device.fileno() is not None:
                selectable.append(tr)
            else:
                tr.thread = self._spawn(tr, until_selectable=False)
        if selectable:
            self._selector_thread = threading.Thread(
                target=self._selector, args=(selectable,), name="hub-selector", daemon=True
            )
            self._selector_thread.start()
        return self

    def stop(self, close_devices: bool = True) -> None:
        self._stop.set()
        if self._selector_thread is not None:
            self._selector_thread.join(timeout=2.0)
        for tr in self.tracks.values():
            if tr.thread is not None:
                tr.thread.join(timeout=2.0)
            if close_devices:
                tr.device.close()

    def __enter__(self) -> Hub:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _spawn(self, tr: _Track, until_selectable: bool) -> threading.Thread:
        th = threading.Thread(target=self._reader, args=(tr, until_selectable), name=f"hub-{tr.name}", daemon=True)
        th.start()
        return th

    def _reader(self, tr: _Track, until_selectable: bool) -> None:
        """A device's own thread: for queue-backed transports (no descriptor to select
        on) for the whole session, and for a selectable device while it is
        disconnected, so its reconnect (an Xbus handshake takes up to seconds) never
        stalls the selector that serves the others."""
        dev = tr.device
        while not self._stop.is_set():
            batch = dev.read_many(0.1)
            self._forward_events(tr)
            if batch:
                self.push_many(tr.name, batch)
            if until_selectable and dev.connected and dev.fileno() is not None:
                return

    def _selector(self, tracks: list[_Track]) -> None:
        """One thread for every device with a file descriptor (serial ports, UDP).

        It waits in ``select`` until some device has data, then sleeps
        ``read_interval`` so that more packets pile up, and drains each ready device
        with one ``read_many``: ~1/read_interval wake-ups per second for the whole
        suit instead of one per packet per device. The sleep is far below the grid's
        ``latency``, so a sample still reaches the frame it belongs to.
        """
        while not self._stop.is_set():
            fds: dict[int, _Track] = {}
            ready: list[_Track] = []
            for tr in tracks:
                if tr.thread is not None:
                    if tr.thread.is_alive():
                        continue  # being reconnected by its own thread
                    tr.thread = None
                dev = tr.device
                fd = dev.fileno() if dev.is_open else None
                if fd is None:
                    if dev.is_open:
                        tr.thread = self._spawn(tr, until_selectable=True)
                    continue
                if dev.has_buffered():
                    ready.append(tr)
                fds[fd] = tr
            if not fds:
                self._stop.wait(0.05)
                continue
            try:
                r, _, _ = select.select(list(fds), [], [], 0.0 if ready else 0.1)
            except (OSError, ValueError):  # a descriptor closed under us: look again
                r = []
                ready = [tr for tr in fds.values()]
            ready.extend(fds[fd] for fd in r if fds[fd] not in ready)
            for tr in ready:
                batch = tr.device.read_many(0.0)
                self._forward_events(tr)
                if batch:
                    self.push_many(tr.name, batch)
            if self.read_interval:
                time.sleep(self.read_interval)  # cheaper than Event.wait; stop() joins within one interval

    def _forward_events(self, tr: _Track) -> None:
        """Copy the device's new connection events to the hub (and its callback)."""
        dev = tr.device
        if not dev.events or dev.events[-1] is tr.last_event:
            return
        evs = list(dev.events)
        new = evs[evs.index(tr.last_event) + 1 :] if tr.last_event in evs else evs
        for ev in new:
            self.events.append(ev)
            if self.on_event:
                self.on_event(ev)
        tr.last_event = evs[-1]

    def push(self, name: str, s: Sample) -> None:
        """Enqueue a sample (reader threads call this; tests and replay may too)."""
        self.push_many(name, (s,))

    def push_many(self, name: str, samples: Sequence[Sample]) -> None:
        """Enqueue samples under one lock; when the queue is full the oldest go and
        are counted (a slow consumer must not make the readers lag)."""
        tr = self.tracks[name]
        with tr.lock:
            excess = len(tr.queue) + len(samples) - tr.queue_size
            if excess > 0:
                tr.dropped += min(excess, len(tr.queue) + len(samples))
                self.stats.queued_dropped[name] = tr.dropped
            tr.queue.extend(samples)

    # --- consumer side ------------------------------------------------------------------------------------
    def _drain(self) -> None:
        """Move queued samples into the rings: per sample only the clock model and
        the gap bookkeeping (plain Python), the ring write once per device."""
        for tr in self.tracks.values():
            with tr.lock:
                if not tr.queue:
                    continue
                batch = list(tr.queue)
                tr.queue.clear()
            now = self.clock()
            worst = 0.0
            imu_t: list[float] = []
            imu: list[Sample] = []
            last_imu = tr.ring.last_t()
            for s in batch:
                st = tr.clock.update(s.device_time, s.t) if s.device_time is not None else s.t
                insole = "force" in s.extra
                if insole:
                    self.insole_names.add(tr.name)
                    last = tr.insole[-1][0] if tr.insole else None
                else:
                    last = last_imu
                lost = s.extra.get("lost_before", 0) if s.extra else 0
                if lost and last is not None:
                    tr.gap_spans.append((last, st))
                    tr.lost_pending += int(lost)
                    self.stats.gaps[tr.name] = self.stats.gaps.get(tr.name, 0) + 1
                if last is not None and st <= last:
                    st = last + 1e-6  # keep per-device times strictly increasing
                if insole:
                    tr.insole.append(
                        (
                            st,
                            np.asarray(s.extra["force"], float),
                            np.asarray(s.extra.get("contacts", np.zeros(4, bool)), bool),
                        )
                    )
                else:
                    imu_t.append(st)
                    imu.append(s)
                    last_imu = st
                    worst = max(worst, now - st)
            if imu:
                tr.ring.extend(imu_t, imu)
            if worst > self.latency:
                self._late(worst, now)

    def _late(self, age: float, now: float) -> None:
        """A sample ``age`` s old reached the hub after its frame's time had passed."""
        self.stats.late += 1
        if self.max_latency is None or age > self.max_latency + self.max_backlog:
            return  # fixed wait, or a backlog (a device's buffer after a reconnect), not a late sample
        if self._last_late is None or now - self._last_late > LATE_QUIET_S:
            self._late_since, self._late_worst = now, 0.0  # a new spell
        self._last_late = now
        self._late_worst = max(self._late_worst, age)
        if now - self._late_since < LATE_PERSIST_S:  # type: ignore[operator]
            return  # one stall so far: counted, not waited for (module docstring)
        wanted = min(self.max_latency, self._late_worst + LATE_MARGIN)
        if wanted > self.latency:
            self.latency = wanted
            self.stats.latency_raised += 1
            self.stats.latency_max = max(self.stats.latency_max, wanted)

    def _relax(self, now: float) -> None:
        """Give the wait back slowly once nothing has been late for a while (a sudden drop
        would release a burst of frames at once)."""
        last, self._last_poll = self._last_poll, now
        if self.latency <= self.base_latency or last is None or self._last_late is None:
            return
        if now - self._last_late > LATE_QUIET_S:
            self.latency = max(self.base_latency, self.latency - LATENCY_RELAX * (now - last))

    @property
    def sites(self) -> tuple[str, ...]:
        return tuple(n for n in self.tracks if n not in self.insole_names)

    def poll(self, now: float | None = None) -> list[HubFrame]:
        """All grid frames that are due (``now - latency``), oldest first."""
        self._drain()
        now = self.clock() if now is None else now
        self._relax(now)
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

    def due_in(self) -> float:
        """Seconds until ``poll`` has the next frame (<= 0: now), so a consumer can wake
        then instead of polling on a timer of its own and adding up to a period."""
        if self._next_index is None:
            return 0.0
        return self._next_index / self.rate + self.latency - self.clock()

    def frames(self, duration: float | None = None) -> Iterator[HubFrame]:
        """Yield frames as they become due, for ``duration`` seconds (or until stopped)."""
        end = None if duration is None else self.clock() + duration
        while not self._stop.is_set() and (end is None or self.clock() < end):
            yield from self.poll()
            nxt = ((self._next_index or 0) / self.rate) + self.latency
            self._stop.wait(max(0.001, min(0.05, nxt - self.clock())))

    def _frames(self, grid: np.ndarray, first: int) -> list[HubFrame]:
        sites = self.sites
        G = grid.size
        lost: dict[str, int] = {}
        for name in sites:
            tr = self.tracks[name]
            if tr.lost_pending:
                lost[name] = tr.lost_pending
                tr.lost_pending = 0
        if self.resampler is None:
            quat, free, acc, gyro, present, newest = self._hold_all(sites, grid)
        elif isinstance(self.resampler, GridResampler) and self.resampler.slerp is not None:
            quat, free, acc, gyro, present, newest = self._interp_all(sites, grid, self.resampler)
        else:
            quat, free, acc, gyro, present, newest = self._per_site(sites, grid)
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
                newest[g, :, 0],
                newest[g, :, 1],
            )
            for g in range(G)
        ]

    def _per_site(self, sites: tuple[str, ...], grid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Grid values site by site: needed when a resampler is injected (it is a
        per-stream callable); also the reference the vectorised hold is tested against."""
        G, S = grid.size, len(sites)
        quat = np.full((G, S, 4), np.nan)
        free = np.full((G, S, 3), np.nan)
        acc = np.full((G, S, 3), np.nan)
        gyro = np.full((G, S, 3), np.nan)
        present = np.zeros((G, S), bool)
        newest = np.full((G, S, 2), np.nan)  # session time, packet counter
        for k, name in enumerate(sites):
            tr = self.tracks[name]
            if not len(tr.ring):
                continue
            rows = tr.ring.rows(grid[0] - 0.5)
            ts = rows[:, 0]
            idx = np.searchsorted(ts, grid, side="right") - 1
            ii = np.maximum(idx, 0)
            interp = self.resampler is not None and tr.ring.has["quat"]
            # interpolating, a grid time only needs samples on both sides no more than
            # fill_gap apart (the resampler checks its own max_gap too)
            reach = max(self.staleness, self.fill_gap) if interp else self.staleness
            ok = (idx >= 0) & (grid - ts[ii] <= reach)
            for a, b in tr.gap_spans:
                if not interp or b - a > self.fill_gap:
                    ok &= ~((grid > a) & (grid < b))
            if interp:
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
            # interpolation reads the sample after the grid time too (and so waits for it)
            last = np.minimum(idx + 1, ts.size - 1) if self.resampler is not None and tr.ring.has["quat"] else ii
            newest[:, k, 0] = ts[last]
            newest[:, k, 1] = rows[last, _Ring.COUNTER]
        for arr in (quat, free, acc, gyro):
            arr[~present] = np.nan
        newest[~present] = np.nan
        return quat, free, acc, gyro, present, newest

    def _hold_all(self, sites: tuple[str, ...], grid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Latest-sample hold for every site at once: ``_interp_all`` with no site
        interpolated (each grid time takes the last row at or before it, missing when older
        than ``staleness`` or inside a gap)."""
        return self._interp_all(sites, grid, None)

    def _interp_all(self, sites: tuple[str, ...], grid: np.ndarray,
                    rs: GridResampler | None) -> tuple[np.ndarray, ...]:
        """``_per_site`` for every site at once: the last rows of every ring stacked into one
        (S, W, COLS) array (``_stack_windows``), each grid time's held row and bracketing pair
        of samples found in one comparison, and with a resampler (``rs``) one batched slerp
        over the (site, grid time) pairs of the sites that send orientation. Per poll a
        fixed handful of numpy calls instead of a full ``to_grid`` per site: with seven
        devices at 60 polls a second those calls held the interpreter lock for a third of
        a capture process's time, beside the drivers and the model (``docs/pipeline.md``).
        Same values as ``_per_site`` (``tests/drivers/test_hub_interp.py``)."""
        S = len(sites)
        rings = [self.tracks[n].ring for n in sites]
        block = _stack_windows(rings, grid[0])
        W = block.shape[1]
        ts = block[:, :, 0]
        ks = np.arange(S)[:, None]
        after = (ts[:, :, None] > grid[None, None, :]).sum(axis=1)  # (S, G); NaN compares False
        idx = W - 1 - after
        ii = np.maximum(idx, 0)
        interp = np.array([rs is not None and r.has["quat"] for r in rings], bool)
        has_free = np.array([r.has["free_acc"] for r in rings], bool)
        reach = np.where(interp, max(self.staleness, self.fill_gap), self.staleness)[:, None]
        ok = (idx >= 0) & (grid[None, :] - ts[ks, ii] <= reach)  # NaN (no row) -> False
        for k, name in enumerate(sites):
            for a, b in self.tracks[name].gap_spans:
                if not interp[k] or b - a > self.fill_gap:
                    ok[k] &= ~((grid > a) & (grid < b))
        # the pair around each grid time, as to_grid picks it (the last pair at the newest sample)
        i1 = np.clip(idx + 1, 1, W - 1)
        i0 = i1 - 1
        t0, t1 = ts[ks, i0], ts[ks, i1]
        dt = t1 - t0
        if rs is not None:
            with np.errstate(invalid="ignore"):
                pair_ok = ((dt <= rs.max_gap + 1e-12) & (grid[None, :] <= ts[:, -1:] + 1e-9)
                           & (t0 <= grid[None, :] + 1e-9))
            ok &= ~interp[:, None] | pair_ok
        held = block[ks, ii]  # (S, G, COLS)
        quat = held[:, :, 1:5].copy()
        free = held[:, :, 5:8].copy()
        sel = ok & interp[:, None]
        if rs is not None and sel.any():
            ka, ga = np.nonzero(sel)
            a, b = i0[ka, ga], i1[ka, ga]
            w = np.clip((grid[ga] - t0[ka, ga]) / dt[ka, ga], 0.0, 1.0)
            quat[ka, ga] = rs.slerp(block[ka, a, 1:5], block[ka, b, 1:5], w)
            lerp = (1.0 - w)[:, None] * block[ka, a, 5:8] + w[:, None] * block[ka, b, 5:8]
            free[ka, ga] = np.where(has_free[ka][:, None], lerp, np.nan)
        free[interp & ~has_free] = np.nan
        # interpolation reads the sample after the grid time too (and so waits for it)
        last = np.where(interp[:, None], np.minimum(idx + 1, W - 1), ii)
        newest = np.stack([ts[ks, last], block[ks, last, _Ring.COUNTER]], axis=-1)
        out = [x.transpose(1, 0, 2).copy() for x in (quat, free, held[:, :, 8:11], held[:, :, 11:14], newest)]
        present = ok.T.copy()
        for arr in out:
            arr[~present] = np.nan
        quat, free, acc, gyro, newest = out
        return quat, free, acc, gyro, present, newest

    def _trim(self) -> None:
        """Forget gap spans that are older than anything a future frame can ask for."""
        if self._next_index is None:
            return
        t_min = self._next_index / self.rate - 1.0
        for tr in self.tracks.values():
            while tr.gap_spans and tr.gap_spans[0][1] < t_min:
                tr.gap_spans.popleft()


def _stack_windows(rings: list[_Ring], t0: float) -> np.ndarray:
    """The last ``W`` rows of every ring as one (S, W, COLS) array (NaN-padded at the
    front), ``W`` doubling from 16 until every window reaches back to ``t0`` (a few rows in
    the steady state) or holds its whole ring."""
    S, W = len(rings), 16
    while True:
        block = np.stack([r.last(W) for r in rings]) if S else np.empty((0, W, _Ring.COLS))
        first_t = block[:, 0, 0]  # NaN where a ring holds fewer than W rows
        short = ~(first_t <= t0) & np.array([len(r) > W for r in rings], bool)
        if not short.any() or W >= rings[0].cap:
            return block
        W *= 2


@dataclass(frozen=True)
class GridResampler:
    """Inference's ``to_grid(t, quat, acc, fps, max_gap, t0)`` in the hub's ``Resampler``
    signature (the app builds it; drivers cannot import inference). With ``slerp``
    (``(q0 (N,4), q1 (N,4), w (N,)) -> unit quats (N,4)``, the same interpolation to_grid
    does) the hub interpolates every site in one batch (``Hub._interp_all``); without it,
    ``to_grid`` per site (``Hub._per_site``, the reference)."""

    to_grid: Callable[..., tuple]
    fps: float = 60.0
    max_gap: float = 0.1
    slerp: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None

    def __call__(self, t: np.ndarray, q: np.ndarray, a: np.ndarray, grid: np.ndarray):
        tg, qg, ag, valid = self.to_grid(t, q, a, fps=self.fps, max_gap=self.max_gap, t0=float(grid[0]))
        G = grid.size
        quat = np.full((G, 4), np.nan)
        acc = np.full((G, 3), np.nan)
        ok = np.zeros(G, bool)
        n = min(G, len(tg))
        quat[:n], acc[:n], ok[:n] = qg[:n], ag[:n], valid[:n]
        return quat, acc, ok


def resampler_from_to_grid(to_grid: Callable[..., tuple], fps: float = 60.0, max_gap: float = 0.1,
                           slerp: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None
                           ) -> GridResampler:
    """The hub's resampler from inference's ``to_grid`` (and, for the batched path, its slerp)."""
    return GridResampler(to_grid, fps, max_gap, slerp)
