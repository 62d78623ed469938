"""The threads that read the devices (``Readers``) and each device's state in the hub (``Track``).

One selector thread serves every device with a socket (UDP): it wakes
once per ``read_interval``, not once per packet, and drains each ready device with
``read_many``, so 13 sensors at 100 Hz cost ~100 wake-ups a second instead of 1300.
Queue-backed transports (python-can's virtual bus, the HID seam) keep a thread of their own,
and a selectable device gets one while it reconnects, so a slow handshake never delays the
others. Every batch read goes to ``deliver`` (the hub's ``push_many``), which queues it.

A serial port (a terminal: a USB serial adapter, a pseudo-terminal) keeps a thread of its own
too. Linux's ``select`` and ``read`` on a terminal with no input ready wait for the kernel's
work that moves the port's received bytes into the line discipline (``n_tty_poll`` ->
``tty_buffer_flush_work``), and on a loaded machine that work waited for a core for seconds:
the selector and the hub's ``poll`` (``catch_up``) sat in that wait together, in
uninterruptible sleep, and a capture put out no frame at all for 1.5-5 s while its devices kept
sending (scripts/stall_watch.py caught it; docs/testing.md). On a thread of its own a terminal's
wait holds up its own samples only.
"""

from __future__ import annotations

import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from drivers.base import Device, DeviceEvent, Sample
from drivers.hub.clock import ClockModel
from drivers.hub.grid import Ring


class Track:
    """One device in the hub: the queue its reader fills (under ``lock``), and on the
    consumer side its clock model, its ring of samples on the session clock, its insole
    samples and the counter gaps not yet past the grid.

    A device of kind ``"tracked"`` (a VR rig: one device, several body sites) has one ring
    per site besides (``site_rings``, by the hub's site name; ``site_of`` maps the device's
    own site name in ``Sample.extra["site"]`` to it): the hub's grid reads those, while
    ``ring`` keeps every sample of the device, so whatever asks a track when it last heard
    from its device (a silent-device check) asks it the same way for every kind. One
    clock model serves all its sites: they share the sender's clock."""

    def __init__(self, name: str, device: Device, queue_size: int, history: int) -> None:
        self.name = name
        self.device = device
        self.queue: deque[Sample] = deque(maxlen=queue_size)
        self.queue_size = queue_size
        self.dropped = 0
        # samples whose time the grid had already put out when they reached the hub: missing from
        # those frames, and so from a recording, which stores the frames (``Hub.status``: ``late``)
        self.missed = 0
        self.battery: float | None = None  # the last level a sample reported
        self.lock = threading.Lock()
        self.clock = ClockModel()
        self.ring = Ring(history)
        self.insole: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=history)
        self.gap_spans: deque[tuple[float, float]] = deque(maxlen=64)
        self.lost_pending = 0
        # s a sample's content is older than its stamp (a VR runtime's tracking latency,
        # ``vmc-in://...&latency_ms=``): the hub dates it that much earlier
        self.age = float(getattr(device, "pose_age", 0.0) or 0.0)
        self.site_of: dict[str, str] = {}
        self.site_rings: dict[str, Ring] = {}
        self.site_gaps: dict[str, deque[tuple[float, float]]] = {}
        if device.kind == "tracked":
            names = getattr(device, "site_names", None) or {s: s for s in device.sites}  # type: ignore[attr-defined]
            self.site_of = dict(names)
            self.site_rings = {n: Ring(history) for n in self.site_of.values()}
            self.site_gaps = {n: deque(maxlen=64) for n in self.site_of.values()}
        self.thread: threading.Thread | None = None
        self.descriptor: tuple[int, bool] | None = None  # (fd, a terminal) as last asked (``is_terminal``)
        self.last_event: DeviceEvent | None = device.events[-1] if device.events else None

    def is_terminal(self, fd: int) -> bool:
        """Whether the device's descriptor ``fd`` is a terminal, which the selector must not
        wait on (module docstring); asked once per descriptor the device has."""
        if self.descriptor is None or self.descriptor[0] != fd:
            try:
                terminal = os.isatty(fd)
            except OSError:
                terminal = False
            self.descriptor = (fd, terminal)
        return self.descriptor[1]


class Readers:
    """The reader threads of ``tracks``: ``start`` opens the devices and starts them,
    ``stop`` (or ``stop_event`` set) ends them. Samples go to ``deliver(name, samples)``,
    the devices' connection events to ``on_event``, both on the reader threads."""

    def __init__(self, tracks: dict[str, Track], deliver: Callable[[str, Sequence[Sample]], None],
                 on_event: Callable[[DeviceEvent], None], read_interval: float, selector: bool,
                 stop_event: threading.Event) -> None:
        self.tracks = tracks
        self.deliver = deliver
        self.on_event = on_event
        self.read_interval = read_interval
        self.selector = selector
        self._stop = stop_event
        self.selector_thread: threading.Thread | None = None
        self._selectable: list[Track] = []
        # the selector's scan and reads, and ``catch_up``'s, one at a time: a device's decoder
        # is not to be read from two threads
        self._read_lock = threading.Lock()

    def start(self) -> None:
        selectable: list[Track] = []
        for tr in self.tracks.values():
            if not tr.device.is_open:
                tr.device.open()
            fd = tr.device.fileno()
            # a selectable device without a descriptor yet (opened while not ready) goes to the
            # selector too: its scan gives it a thread until it reconnects and takes it back then
            # (or keeps it there for good, a terminal)
            if self.selector and (fd is not None and not tr.is_terminal(fd)
                                  or fd is None and tr.device.selectable):
                selectable.append(tr)
            else:
                tr.thread = self._spawn(tr, until_selectable=False)
        self._selectable = selectable
        if selectable:
            self.selector_thread = threading.Thread(
                target=self._select, args=(selectable,), name="hub-selector", daemon=True
            )
            self.selector_thread.start()

    def stop(self, close_devices: bool = True) -> None:
        self._stop.set()
        if self.selector_thread is not None:
            self.selector_thread.join(timeout=2.0)
        for tr in self.tracks.values():
            if tr.thread is not None:
                tr.thread.join(timeout=2.0)
            if close_devices:
                tr.device.close()

    def _spawn(self, tr: Track, until_selectable: bool) -> threading.Thread:
        th = threading.Thread(target=self._read, args=(tr, until_selectable), name=f"hub-{tr.name}", daemon=True)
        th.start()
        return th

    def _read(self, tr: Track, until_selectable: bool) -> None:
        """A device's own thread: for queue-backed transports (no descriptor to select
        on) and terminals for the whole session, and for a socket device while it is
        disconnected, so its reconnect never stalls the selector that serves the others."""
        dev = tr.device
        while not self._stop.is_set():
            batch = dev.read_many(0.1)
            self.forward_events(tr)
            if batch:
                self.deliver(tr.name, batch)
            fd = dev.fileno() if dev.connected else None
            if fd is not None and tr.is_terminal(fd):
                until_selectable = False  # a terminal keeps this thread (module docstring)
                if batch and self.read_interval:
                    time.sleep(self.read_interval)  # let packets pile up, as the selector does
            elif until_selectable and fd is not None:
                return

    def _select(self, tracks: list[Track]) -> None:
        """One thread for every device with a file descriptor (serial ports, UDP).

        It waits in ``select`` until some device has data, then sleeps
        ``read_interval`` so that more packets pile up, and drains each ready device
        with one ``read_many``: ~1/read_interval wake-ups per second for the whole
        suit instead of one per packet per device. The sleep is far below the grid's
        ``latency``, so a sample still reaches the frame it belongs to.
        """
        while not self._stop.is_set():
            with self._read_lock:
                fds, ready = self._scan(tracks)
            if not fds:
                self._stop.wait(0.05)
                continue
            try:
                r, _, _ = select.select(list(fds), [], [], 0.0 if ready else 0.1)
            except (OSError, ValueError):  # a descriptor closed under us: look again
                r = []
                ready = list(fds.values())
            ready.extend(fds[fd] for fd in r if fds[fd] not in ready)
            with self._read_lock:
                self._read_ready(ready)
            if self.read_interval:
                time.sleep(self.read_interval)  # cheaper than Event.wait; stop() joins within one interval

    def catch_up(self) -> None:
        """Read, on the caller's thread, whatever the selector's devices hold right now.

        The hub's ``poll`` calls this before it puts samples on the grid. When the
        process stalls (a turn on a core it waits for, a collection, a thread that holds
        the interpreter), the selector and the thread that polls resume together, and
        whichever ran first decided whether the samples that arrived meanwhile made their
        frames: beside the test suite a capture's serial and UDP sensors went missing
        together for 0.2-1.1 s at a time while its CAN sensors, whose threads block on
        their own queues, did not. Read here first, the samples waiting in the kernel's
        buffers are on the grid before the frames they belong to go out: their times come
        from the device clocks (``ClockModel``), not from when they were read. A stream
        with no clock of its own (a BNO08x in RVC mode) is stamped when read, so this
        helps it only when the thread that polls is running while the selector is not."""
        if not self._selectable or self._stop.is_set():
            return
        with self._read_lock:
            fds, ready = self._scan(self._selectable, spawn=False)
            if not fds:
                return
            try:
                r, _, _ = select.select(list(fds), [], [], 0.0)
            except (OSError, ValueError):
                return  # a descriptor closed under us: the selector sorts it out
            ready.extend(fds[fd] for fd in r if fds[fd] not in ready)
            self._read_ready(ready)

    def _scan(self, tracks: list[Track], spawn: bool = True) -> tuple[dict[int, Track], list[Track]]:
        """The descriptors to wait on, and the devices whose own buffers already hold data.
        A device without a descriptor while open is reconnecting: ``spawn`` gives it a thread
        of its own until it has one again (the selector does; ``catch_up`` passes it over)."""
        fds: dict[int, Track] = {}
        ready: list[Track] = []
        for tr in tracks:
            if tr.thread is not None:
                if tr.thread.is_alive() or not spawn:
                    continue  # being reconnected by its own thread
                tr.thread = None
            dev = tr.device
            fd = dev.fileno() if dev.is_open else None
            if fd is None:
                if dev.is_open and spawn:
                    tr.thread = self._spawn(tr, until_selectable=True)
                continue
            if tr.is_terminal(fd):  # reconnected as a terminal: a thread of its own from now on
                if spawn:
                    tr.thread = self._spawn(tr, until_selectable=False)
                continue
            if dev.has_buffered():
                ready.append(tr)
            fds[fd] = tr
        return fds, ready

    def _read_ready(self, ready: list[Track]) -> None:
        for tr in ready:
            batch = tr.device.read_many(0.0)
            self.forward_events(tr)
            if batch:
                self.deliver(tr.name, batch)

    def forward_events(self, tr: Track) -> None:
        """Pass the device's new connection events on."""
        dev = tr.device
        if not dev.events or dev.events[-1] is tr.last_event:
            return
        evs = list(dev.events)
        new = evs[evs.index(tr.last_event) + 1 :] if tr.last_event in evs else evs
        for ev in new:
            self.on_event(ev)
        tr.last_event = evs[-1]
