"""The hub: many devices at once, merged on one session clock and put on the 60 Hz grid.

The pieces live beside it (``drivers/hub/__init__.py`` says why each exists): the reader
threads and per-device state (``readers``), the clock model (``clock``), the grid values
(``grid``). Here: the queues drained onto the session clock, the grid's wait for late
samples, and the frames.

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
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.base import Device, DeviceEvent, Sample
from drivers.hub import grid as grid_values
from drivers.hub.grid import Interpolation, Ring
from drivers.hub.readers import Readers, Track


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
    # per site: a tracked device's position (m, in its own frame: a VR runtime's, Z up, floor
    # at 0), NaN at sites with none (IMUs) and where the site is not present; None from
    # sources without tracked devices (IMU-only hubs, synthetic frames, older recordings)
    position: np.ndarray | None = None


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


class Hub:
    """Merge ``devices`` (name -> opened or unopened device) onto a ``rate`` Hz grid.

    Names are sensor sites; a device whose samples carry insole channels
    (``extra['force']``) feeds the insole part of the frame instead, and a device of kind
    ``"tracked"`` (a VR rig, ``drivers/vmc``) stands for several sites: its samples are
    routed by ``extra['site']`` to one site each (named by the device's ``site_names``),
    which the frames carry like IMU sites, in the device's order at the device's place.
    interpolation: how to interpolate to the grid (``grid.Interpolation``; None: hold the
    latest sample).
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
        interpolation: Interpolation | None = None,
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
        # far less than the poser guessing the site; so when interpolating, gaps up to
        # ``fill_gap`` s are bridged.
        self.fill_gap = fill_gap
        self.latency = latency
        self.base_latency = latency
        self.max_latency = max_latency if max_latency is None else max(max_latency, latency)
        self._last_late: float | None = None
        self._late_since: float | None = None  # when the current spell of late samples began
        self._late_worst = 0.0  # the oldest sample of that spell
        self._last_poll: float | None = None
        self.staleness = staleness
        self.max_backlog = max_backlog
        self.interpolation = interpolation
        self.clock = clock
        self.on_event = on_event
        self.tracks = {n: Track(n, d, queue_size, history=512) for n, d in devices.items()}
        taken: dict[str, str] = {}
        for n, tr in self.tracks.items():
            for site in tr.site_rings or (n,):
                if site in taken:
                    raise ValueError(f"site {site} is given twice: by device {taken[site]} and by device {n}")
                taken[site] = n
        self._site_rings: dict[str, tuple[Ring, deque[tuple[float, float]]]] = {}
        for n, tr in self.tracks.items():
            self._site_rings.update({s: (r, tr.site_gaps[s]) for s, r in tr.site_rings.items()} if tr.site_rings
                                    else {n: (tr.ring, tr.gap_spans)})
        self.insole_names: set[str] = {n for n, d in devices.items() if d.kind == "insoles"}
        # a tracked device's sites carry positions: the frames then hold them (``HubFrame.position``)
        self._tracked = any(tr.site_rings for tr in self.tracks.values())
        self.stats = HubStats()
        self._stop = threading.Event()
        self._next_index: int | None = None
        self.events: deque[DeviceEvent] = deque(maxlen=256)
        # the selector's sleep between drains; default one grid period: a sample waits at
        # most one frame before it is queued, well inside ``latency`` (13 x 100 Hz: 0.10 of a
        # core at 10 ms, 0.08 at 16.7 ms, docs/devices.md)
        self.readers = Readers(self.tracks, self.push_many, self._device_event,
                               read_interval=min(1.0 / rate if read_interval is None else read_interval, latency / 2),
                               selector=selector, stop_event=self._stop)

    # --- threads ------------------------------------------------------------------------------------------
    def start(self) -> Hub:
        self.readers.start()
        return self

    def stop(self, close_devices: bool = True) -> None:
        self.readers.stop(close_devices)

    def __enter__(self) -> Hub:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _device_event(self, ev: DeviceEvent) -> None:
        """A device's connection event (on its reader thread): kept, and passed to ``on_event``."""
        self.events.append(ev)
        if self.on_event:
            self.on_event(ev)

    def push(self, name: str, s: Sample) -> None:
        """Enqueue a sample (reader threads call this; tests and replay may too)."""
        self.push_many(name, (s,))

    def push_many(self, name: str, samples: Sequence[Sample]) -> None:
        """Enqueue samples under one lock; when the queue is full the oldest go and
        are counted (a slow consumer must not make the readers lag). Every reader path
        ends here, so the device's last battery level is taken here too."""
        tr = self.tracks[name]
        for s in reversed(samples):
            if s.battery is not None:
                tr.battery = float(s.battery)
                break
        with tr.lock:
            excess = len(tr.queue) + len(samples) - tr.queue_size
            if excess > 0:
                tr.dropped += min(excess, len(tr.queue) + len(samples))
                self.stats.queued_dropped[name] = tr.dropped
            tr.queue.extend(samples)

    def wait_status(self) -> dict[str, Any]:
        """The grid's wait for late samples now, how many samples came late, how often and
        how far the wait grew for them: what a session reports beside its latency."""
        return {"wait_ms": round(self.latency * 1e3, 1), "late": self.stats.late,
                "wait_raised": self.stats.latency_raised, "wait_max_ms": round(self.stats.latency_max * 1e3, 1)}

    def status(self) -> dict[str, dict[str, Any]]:
        """Per device, for a status panel: packets decoded, errors, gaps, lost packets,
        queue drops, samples too late for their frames, reconnects, battery (None if unknown)."""
        out = {}
        for name, tr in self.tracks.items():
            st = tr.device.stats
            out[name] = {
                "packets": int(st.decoded), "errors": int(st.errors), "gaps": int(self.stats.gaps.get(name, 0)),
                "lost": int(st.lost_packets), "dropped": int(tr.dropped), "late": int(tr.missed),
                "reconnects": int(st.reconnects), "battery": tr.battery,
            }
        return out

    # --- consumer side ------------------------------------------------------------------------------------
    def _drain(self) -> None:
        """Move queued samples into the rings: per sample only the clock model and
        the gap bookkeeping (plain Python), the ring write once per device."""
        put_out = -math.inf if self._next_index is None else (self._next_index - 1) / self.rate
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
                st = (tr.clock.update(s.device_time, s.t) if s.device_time is not None else s.t) - tr.age
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
                if st <= put_out:
                    tr.missed += 1
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
                if tr.site_rings:
                    self._route(tr, imu_t, imu)
            if worst > self.latency:
                self._late(worst, now)

    @staticmethod
    def _route(tr: Track, ts: list[float], samples: list[Sample]) -> None:
        """A tracked device's samples into their sites' rings (a site the device does not
        name is passed over: the device counts those itself)."""
        by: dict[str, tuple[list[float], list[Sample]]] = {}
        for t, s in zip(ts, samples, strict=True):
            site = tr.site_of.get(s.extra.get("site", ""))
            if site is not None:
                b = by.setdefault(site, ([], []))
                b[0].append(t)
                b[1].append(s)
        for site, (t_site, s_site) in by.items():
            tr.site_rings[site].extend(t_site, s_site)

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
        out: list[str] = []
        for n, tr in self.tracks.items():
            if tr.site_rings:
                out += tr.site_rings
            elif n not in self.insole_names:
                out.append(n)
        return tuple(out)

    def _ring(self, site: str) -> tuple[Ring, deque[tuple[float, float]]]:
        """A site's ring and counter gaps: its device's, or its tracked device's for that site."""
        return self._site_rings[site]

    def poll(self, now: float | None = None) -> list[HubFrame]:
        """All grid frames that are due (``now - latency``), oldest first. The devices the
        selector reads are read first (``Readers.catch_up``): a stall of the process must not
        decide which of the samples it held up make their frames."""
        self.readers.catch_up()
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
            tr = self.tracks.get(name)
            if tr is not None and tr.lost_pending:
                lost[name] = tr.lost_pending
                tr.lost_pending = 0
        if self.interpolation is not None and self.interpolation.per_stream is not None:
            quat, free, acc, gyro, present, newest = self._per_site(sites, grid)
        else:
            quat, free, acc, gyro, present, newest = self._interp_all(sites, grid, self.interpolation)
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
        position = (grid_values.positions([self._ring(n)[0] for n in sites], grid, present, self.interpolation)
                    if self._tracked else None)
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
                None if position is None else position[g],
            )
            for g in range(G)
        ]

    def _per_site(self, sites: tuple[str, ...], grid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Grid values site by site (``grid.per_stream``), through the interpolation's
        per-stream resampler when it has one, else held: the reference of ``_interp_all``."""
        per = self.interpolation.per_stream if self.interpolation is not None else None
        rings = [self._ring(n) for n in sites]
        return grid_values.per_stream([r for r, _ in rings], [g for _, g in rings], grid, self.staleness,
                                      self.fill_gap, per)

    def _hold_all(self, sites: tuple[str, ...], grid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Latest-sample hold for every site at once: ``_interp_all`` with no site interpolated."""
        return self._interp_all(sites, grid, None)

    def _interp_all(self, sites: tuple[str, ...], grid: np.ndarray,
                    interpolation: Interpolation | None) -> tuple[np.ndarray, ...]:
        """Grid values of every site at once (``grid.batched``)."""
        rings = [self._ring(n) for n in sites]
        return grid_values.batched([r for r, _ in rings], [g for _, g in rings], grid, self.staleness, self.fill_gap,
                                   interpolation)

    def _trim(self) -> None:
        """Forget gap spans that are older than anything a future frame can ask for."""
        if self._next_index is None:
            return
        t_min = self._next_index / self.rate - 1.0
        for tr in self.tracks.values():
            while tr.gap_spans and tr.gap_spans[0][1] < t_min:
                tr.gap_spans.popleft()

