"""One python-can bus per CAN channel in a process, shared by every device on it.

Why: a python-can bus receives every frame on its channel. With one bus per
sensor, N sensors on one channel make the process receive (and, on python-can's
``virtual`` interface, deep-copy) every frame N times and decode N x the traffic
in Python. Here the first device on a channel opens the bus, the others attach
to it, and the last one to leave shuts it down.

Reading is leader/follower under one lock, so that no extra thread is needed and
each device's reader thread keeps calling its own ``recv``: a device with frames
queued takes one; otherwise, if nobody is reading, it becomes the reader, calls
``bus.recv`` (outside the lock, at most ``POLL_S`` at a time so a hand-over is
never far away), routes what arrived to the queues of the devices that own those
identifiers and wakes them; if someone else is reading, it waits on its own
condition. Whoever leaves ``recv`` while nobody reads wakes a waiter to take the
role. Frames nobody owns are dropped without decoding; CAN error frames go to
the device whose thread read them.

A ``Tap`` (one device's view) offers the part of python-can's ``BusABC`` a
device uses, ``recv``, ``send`` and ``shutdown``, so a driver holds it where it
held a bus.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

import can

from ..base import DeviceGone

POLL_S = 0.05  # longest single bus.recv: bounds how long a hand-over of the reader role can wait
DRAIN_MAX = 256  # frames taken per lock round-trip once the first one arrived
QUEUE_FRAMES = 4096  # per device: ~6 s of an MTi at 100 Hz, 7 frames per sample
KERNEL_FILTERING = frozenset({"socketcan"})  # interfaces whose can_filters act in the kernel, not in Python
ID_MASK = 0x1FFFFFFF  # exact match, standard or extended (routing ignores the flag, as decoding does)

BusKey = tuple[str, str, str]


def bus_key(interface: str, channel: str, kwargs: dict[str, Any]) -> BusKey:
    """Buses opened with the same interface, channel and options are the same bus
    (the options are compared by their repr, because some are unhashable)."""
    return (interface, str(channel), repr(sorted(kwargs.items())))


class Tap:
    """One device's view of a shared bus: the frames of its own identifiers, in
    arrival order, in a bounded queue (the oldest go first, counted in ``dropped``)."""

    def __init__(self, shared: SharedBus, ids: frozenset[int], queue_size: int) -> None:
        self.shared = shared
        self.ids = ids
        self.frames: deque[can.Message] = deque()
        self.queue_size = queue_size
        self.dropped = 0
        self.closed = False
        self.cond = threading.Condition(shared.lock)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """Next frame of ours (or an error frame this thread read); ``None`` after
        ``timeout``; ``DeviceGone`` once the tap is shut down or the bus failed."""
        return self.shared.recv(self, timeout)

    def send(self, msg: can.Message) -> None:
        self.shared.send(self, msg)

    def shutdown(self) -> None:
        """Leave the bus (idempotent); the last tap to leave shuts the bus down."""
        self.shared.registry.release(self)

    def put(self, msg: can.Message) -> None:
        """Queue a routed frame (caller holds the bus lock)."""
        if len(self.frames) >= self.queue_size:
            self.frames.popleft()
            self.dropped += 1
        self.frames.append(msg)


class SharedBus:
    """A python-can bus and the taps attached to it. Every field below is guarded by
    ``lock``, except ``bus`` itself, which only the current reader (``reading``)
    receives from, with the lock released."""

    def __init__(self, registry: BusRegistry, key: BusKey, bus: can.BusABC, kernel_filters: bool) -> None:
        self.registry = registry
        self.key = key
        self.bus = bus
        self.kernel_filters = kernel_filters
        self.lock = threading.Lock()
        self.taps: list[Tap] = []
        self.routes: dict[int, tuple[Tap, ...]] = {}
        self.waiting: list[Tap] = []  # taps with a thread in cond.wait, longest waiting first
        self.reading = False
        self.error: BaseException | None = None
        self.closed = False  # no taps left: shut down, or shut down by the reader when it returns
        self._shut = False
        self._send_lock = threading.Lock()

    # --- membership (the registry calls these with its own lock held, then this one) -----------------
    def attach(self, ids: frozenset[int], queue_size: int) -> Tap:
        with self.lock:
            tap = Tap(self, ids, queue_size)
            self.taps.append(tap)
            self._reroute()
            return tap

    def detach(self, tap: Tap) -> bool:
        """Remove ``tap``; True if it was the last one (the bus is then closed)."""
        with self.lock:
            if tap.closed:
                return False
            tap.closed = True
            tap.cond.notify_all()
            self.taps.remove(tap)
            self._reroute()
            if self.taps:
                return False
            self.closed = True
            if not self.reading:
                self._shutdown()
            return True

    def _reroute(self) -> None:
        routes: dict[int, list[Tap]] = {}
        for tap in self.taps:
            for i in tap.ids:
                routes.setdefault(i, []).append(tap)
        self.routes = {i: tuple(t) for i, t in routes.items()}
        if self.kernel_filters and not self.closed and self.error is None:
            self._install_filters()

    def _install_filters(self) -> None:
        """Let the kernel drop foreign traffic before Python sees it (socketcan)."""
        filters = [{"can_id": i, "can_mask": ID_MASK} for i in sorted(self.routes)] or None
        try:
            self.bus.set_filters(filters)
        except (can.CanError, OSError):
            pass  # routing still drops foreign frames, only later

    def _shutdown(self) -> None:
        if self._shut:
            return
        self._shut = True
        try:
            self.bus.shutdown()
        except Exception:  # a broken bus may fail to close, with its interface's own error; it is gone either way
            # python-can's finaliser would call the failing shutdown again, from the garbage collector
            # (python-can-remote's does once its server has gone): mark it shut down as BusABC does
            can.BusABC.shutdown(self.bus)

    # --- receiving ------------------------------------------------------------------------------------
    def recv(self, tap: Tap, timeout: float | None) -> can.Message | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        with self.lock:
            try:
                return self._next_frame(tap, deadline)
            finally:
                self._pass_reader_role()

    def _next_frame(self, tap: Tap, deadline: float | None) -> can.Message | None:
        polled = False  # a zero timeout still looks at the bus once
        while True:
            self._check(tap)
            if tap.frames:
                return tap.frames.popleft()
            remaining = None if deadline is None else deadline - time.monotonic()
            expired = remaining is not None and remaining <= 0
            if not self.reading and not (expired and polled):
                self._read_as_leader(tap, POLL_S if remaining is None else max(0.0, min(POLL_S, remaining)))
                polled = True
                continue
            if expired:
                return None
            self._wait(tap, remaining)

    def _check(self, tap: Tap) -> None:
        if tap.closed:
            raise DeviceGone("bus closed")
        if self.error is not None:
            raise DeviceGone(f"CAN bus {self.key[0]}/{self.key[1]}: {self.error}")

    def _wait(self, tap: Tap, timeout: float | None) -> None:
        self.waiting.append(tap)
        try:
            tap.cond.wait(timeout)
        finally:
            self.waiting.remove(tap)

    def _pass_reader_role(self) -> None:
        """Leaving ``recv`` with nobody reading: wake the longest waiter to read. Every
        exit does this, so a wake-up that found frames and left passes it on."""
        if not self.reading and self.waiting:
            self.waiting[0].cond.notify()

    def _read_as_leader(self, tap: Tap, timeout: float) -> None:
        """Receive with the lock released, then route (lock held again)."""
        self.reading = True
        self.lock.release()
        try:
            msgs, exc = self._pull(timeout), None
        except Exception as e:  # a bus that raises, whatever its interface's type, is broken
            msgs, exc = [], e
            self.registry.forget(self)  # outside our lock: the registry's lock comes first
        finally:
            self.lock.acquire()
            self.reading = False
        if exc is not None:
            self._fail(exc)
        else:
            self._route(tap, msgs)
        if self.closed:
            self._shutdown()  # the last tap left while we were receiving

    def _pull(self, timeout: float) -> list[can.Message]:
        first = self.bus.recv(timeout)
        if first is None:
            return []
        out = [first]
        while len(out) < DRAIN_MAX:
            msg = self.bus.recv(0.0)
            if msg is None:
                break
            out.append(msg)
        return out

    def _route(self, reader: Tap, msgs: list[can.Message]) -> None:
        woken: set[Tap] = set()
        routes = self.routes
        for msg in msgs:
            targets = (reader,) if msg.is_error_frame else routes.get(msg.arbitration_id)
            if not targets:
                continue  # another node's traffic: never decoded
            for t in targets:
                t.put(msg)
            woken.update(targets)
        for t in woken:
            t.cond.notify()

    def _fail(self, exc: BaseException) -> None:
        """The bus is broken: every tap gets ``DeviceGone`` (their devices reconnect,
        and the registry, which already forgot this bus, opens a fresh one)."""
        self.error = exc
        for t in self.taps:
            t.cond.notify_all()

    # --- sending --------------------------------------------------------------------------------------
    def send(self, tap: Tap, msg: can.Message) -> None:
        with self.lock:
            self._check(tap)
        try:
            with self._send_lock:
                self.bus.send(msg)
        except Exception as exc:  # as in _read_as_leader: any interface's failure
            raise DeviceGone(f"CAN send on {self.key[0]}/{self.key[1]}: {exc}") from exc


class BusRegistry:
    """The shared buses of one side of a process, by (interface, channel, options).

    Drivers use ``BUSES``; a simulator that sends on the same channel in the same
    process keeps a registry of its own, because python-can does not hand a bus
    its own frames back.
    """

    def __init__(self, factory: Callable[..., can.BusABC] = can.Bus) -> None:
        self._factory = factory
        self._lock = threading.Lock()
        self._buses: dict[BusKey, SharedBus] = {}

    def attach(
        self,
        interface: str,
        channel: str,
        kwargs: dict[str, Any] | None = None,
        ids: Iterable[int] = (),
        queue_size: int = QUEUE_FRAMES,
    ) -> Tap:
        """A tap on the bus for (interface, channel, kwargs), opening the bus if this is
        the first. Raises what ``can.Bus`` raises when it cannot be opened."""
        kwargs = dict(kwargs or {})
        key = bus_key(interface, channel, kwargs)
        with self._lock:
            shared = self._buses.get(key)
            if shared is None:
                bus = self._factory(interface=interface, channel=channel, **kwargs)
                shared = SharedBus(self, key, bus, kernel_filters=interface in KERNEL_FILTERING)
                self._buses[key] = shared
            return shared.attach(frozenset(ids), queue_size)

    def release(self, tap: Tap) -> None:
        with self._lock:
            shared = tap.shared
            if shared.detach(tap) and self._buses.get(shared.key) is shared:
                del self._buses[shared.key]

    def forget(self, shared: SharedBus) -> None:
        """Stop handing out ``shared`` (it failed): the next attach opens a new bus."""
        with self._lock:
            if self._buses.get(shared.key) is shared:
                del self._buses[shared.key]

    def open_buses(self) -> list[SharedBus]:
        """The buses currently handed out (for diagnostics and tests)."""
        with self._lock:
            return list(self._buses.values())


BUSES = BusRegistry()
"""Every ``XsensCanDevice`` of the process attaches here."""
