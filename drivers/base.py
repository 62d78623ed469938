"""The device base every backend builds on, in the spirit of python-can's ``BusABC``.

A backend overrides ``_open``, ``_close`` and one ``_read(timeout)``; everything a
caller relies on (session timestamps, counter-gap accounting, statistics,
reconnecting with backoff when a port vanishes, iteration, context manager) lives
here once, so the five backends behave identically under failure.

Why a session clock stamp in ``read`` and not in the backend: the hub merges many
devices on one monotonic clock, so every sample must be stamped the same way, at
the moment the bytes were decoded.
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np


class DeviceGone(OSError):
    """The transport vanished (port unplugged, socket closed). The base reconnects."""


class DeviceNotReady(DeviceGone):
    """The transport opened, but the device on it is not taking what is written to it yet
    (a serial write that timed out: the other end is not reading). Unlike a port that is
    not there (a typo in the URL), this is a device that is there but busy or still
    starting: ``Device.open`` opens it disconnected and the reconnect loop configures it
    once it reads again."""


@dataclass(slots=True)
class Sample:
    """One decoded measurement of one sensor.

    Vectors are float64 numpy arrays or ``None`` when the device does not report
    that quantity. Frames follow DESIGN.md: ``quat`` (w, x, y, z) sensor -> world
    (Z up), ``free_acc`` world m/s^2 without gravity, ``acc`` specific force in the
    sensor frame (a still sensor reads +9.81 up), ``gyro`` rad/s sensor frame.
    """

    t: float
    device_time: float | None
    device_id: str
    counter: int | None = None
    quat: np.ndarray | None = None
    free_acc: np.ndarray | None = None
    acc: np.ndarray | None = None
    gyro: np.ndarray | None = None
    battery: float | None = None
    status: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        """Plain-JSON view (lists and floats), used by ``devices probe``."""
        out: dict[str, Any] = {
            "t": self.t,
            "device_time": self.device_time,
            "device_id": self.device_id,
            "counter": self.counter,
        }
        for name in ("quat", "free_acc", "acc", "gyro"):
            v = getattr(self, name)
            if v is not None:
                out[name] = [float(x) for x in v]
        if self.battery is not None:
            out["battery"] = self.battery
        if self.status is not None:
            out["status"] = self.status
        for k, v in self.extra.items():
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return out


@dataclass(slots=True)
class DeviceEvent:
    """Something a user should see but that is not an error of the program."""

    t: float
    device_id: str
    kind: str  # "opened", "disconnected", "reconnected", "reconnect_failed", "closed"
    detail: str = ""


@dataclass
class DeviceStats:
    """Counters a UI shows and tests assert on; all monotonically increasing."""

    decoded: int = 0
    bad_checksum: int = 0
    bad_frame: int = 0
    resyncs: int = 0
    counter_gaps: int = 0
    lost_packets: int = 0
    timeouts: int = 0
    disconnects: int = 0
    reconnects: int = 0

    @property
    def errors(self) -> int:
        return self.bad_checksum + self.bad_frame + self.lost_packets

    def as_dict(self) -> dict[str, int]:
        return {
            k: getattr(self, k)
            for k in (
                "decoded",
                "bad_checksum",
                "bad_frame",
                "resyncs",
                "counter_gaps",
                "lost_packets",
                "timeouts",
                "disconnects",
                "reconnects",
            )
        }


class CounterTracker:
    """Turns a wrapping packet counter into lost-packet counts.

    A jump backwards by more than half the range is treated as a device restart,
    not as 60000 lost packets.
    """

    __slots__ = ("modulus", "last")

    def __init__(self, modulus: int) -> None:
        self.modulus = modulus
        self.last: int | None = None

    def update(self, counter: int) -> int:
        """Return the number of packets missing before ``counter``."""
        last, self.last = self.last, counter
        if last is None:
            return 0
        gap = (counter - last - 1) % self.modulus
        if gap >= self.modulus // 2:  # duplicate, reorder or device restart
            return 0
        return gap

    def reset(self) -> None:
        self.last = None


class Unwrapper:
    """Unwraps a device clock that counts modulo ``modulus`` ticks into seconds.

    Devices report time in wrapping integer ticks (the DualSense 32-bit clock wraps
    every ~24 minutes); the hub's drift fit needs a monotonic device time.
    """

    __slots__ = ("modulus", "tick", "_last", "_offset")

    def __init__(self, modulus: int, tick: float) -> None:
        self.modulus = modulus
        self.tick = tick
        self._last: int | None = None
        self._offset = 0

    def update(self, raw: int) -> float:
        if self._last is not None and raw < self._last and (self._last - raw) > self.modulus // 2:
            self._offset += self.modulus
        self._last = raw
        return (raw + self._offset) * self.tick

    def reset(self) -> None:
        self._last = None
        self._offset = 0


class Device(ABC):
    """Base of every backend.

    Subclasses set ``scheme`` and ``counter_modulus`` and implement ``_open``,
    ``_close`` and ``_read``. ``_read(timeout)`` returns a ``Sample`` (with ``t``
    left for the base to stamp if it is 0.0), ``None`` on timeout, or raises
    ``DeviceGone`` / ``OSError`` when the transport is gone. Decode errors are
    never raised: backends count them in ``self.stats``.
    """

    scheme: ClassVar[str] = ""
    kind: ClassVar[str] = "imu"  # "imu" or "insoles": what the hub does with the samples
    counter_modulus: ClassVar[int | None] = None

    def __init__(
        self,
        device_id: str,
        *,
        clock: Callable[[], float] = time.monotonic,
        reconnect: bool = True,
        backoff: tuple[float, float] = (0.05, 2.0),
        on_event: Callable[[DeviceEvent], None] | None = None,
    ) -> None:
        self.device_id = device_id
        self.clock = clock
        self.reconnect = reconnect
        self.backoff_min, self.backoff_max = backoff
        self.on_event = on_event
        self.stats = DeviceStats()
        self.events: deque[DeviceEvent] = deque(maxlen=256)
        self._counter = CounterTracker(self.counter_modulus) if self.counter_modulus else None
        self._is_open = False
        self._connected = False
        self._next_attempt = 0.0
        self._backoff = self.backoff_min
        self._lock = threading.RLock()
        self._deferred_loss: OSError | None = None

    # --- lifecycle -------------------------------------------------------------------------------------
    def open(self) -> Device:
        """Open the transport. Raises if the device is not there at all (a typo in
        the URL must be an error, not an endless reconnect loop); one that is there but not
        taking writes yet (``DeviceNotReady``) opens disconnected, and reconnects."""
        with self._lock:
            if not self._is_open:
                try:
                    self._open()
                except DeviceNotReady as exc:
                    if not self.reconnect:
                        raise
                    self._is_open = self._connected = True
                    self._event("opened", self.describe())
                    self._lost(exc)  # as a loss: the reconnect loop's backoff takes it from here
                    return self
                self._is_open = self._connected = True
                self._event("opened", self.describe())
        return self

    def close(self) -> None:
        with self._lock:
            if self._is_open:
                self._is_open = False
                if self._connected:
                    self._safe_close()
                self._connected = False
                self._event("closed")

    def __enter__(self) -> Device:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        return self._is_open

    @property
    def connected(self) -> bool:
        return self._connected

    def describe(self) -> str:
        """A line for logs and the CLI."""
        return f"{self.scheme}:{self.device_id}"

    # --- reading --------------------------------------------------------------------------------------
    def read(self, timeout: float | None = 0.1) -> Sample | None:
        """Next sample or ``None`` after ``timeout`` seconds (``None`` = wait forever).

        Never raises for transport loss while ``reconnect`` is on: the loss becomes a
        ``disconnected`` event and later a ``reconnected`` one.
        """
        sample = self._guarded(self._read, timeout)
        return None if sample is None else self._finish(sample, self.clock())

    def read_many(self, timeout: float | None = 0.1, max_samples: int = 256) -> list[Sample]:
        """Every sample that is available now, waiting up to ``timeout`` for the first;
        ``[]`` on timeout. Same loss/reconnect behaviour as ``read``.

        Why: at 13 sensors x 100 Hz the cost is in waking up once per packet, not in
        decoding. A reader that wakes every few milliseconds and takes the whole
        buffer pays the wake-up, the syscalls and the locking once per batch.
        """
        batch = self._guarded(lambda t: self._read_many(t, max_samples) or None, timeout)
        if not batch:
            return []
        now = self.clock()  # one stamp per batch: these bytes were all decoded now
        return [self._finish(s, now) for s in batch]

    def _guarded(self, fn: Callable[[float | None], Any], timeout: float | None) -> Any:
        """Run ``fn(remaining)`` until it returns something or ``timeout`` passes, turning
        transport loss into reconnect with backoff (the part ``read`` and ``read_many``
        share)."""
        if not self._is_open:
            raise RuntimeError(f"{self.describe()} is not open")
        deadline = None if timeout is None else self.clock() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - self.clock())
            if not self._connected:
                if not self._try_reconnect():
                    wait = self._next_attempt - self.clock()
                    if remaining is not None and wait >= remaining:
                        time.sleep(remaining)
                        self._count_timeout(timeout)
                        return None
                    time.sleep(max(0.0, min(wait, 0.05)))
                    continue
                remaining = None if deadline is None else max(0.0, deadline - self.clock())
            try:
                exc, self._deferred_loss = self._deferred_loss, None
                if exc is not None:
                    raise exc
                result = fn(remaining)
            except OSError as exc:  # includes DeviceGone and serial.SerialException
                self._lost(exc)
                if not self.reconnect:
                    raise
                continue
            if result is not None:
                return result
            if remaining is not None and self.clock() >= deadline:  # type: ignore[operator]
                self._count_timeout(timeout)
                return None

    def _count_timeout(self, timeout: float | None) -> None:
        # a zero-timeout poll (the hub's selector asking "anything more?") is not a timeout
        if timeout != 0.0:
            self.stats.timeouts += 1

    def fileno(self) -> int | None:
        """A file descriptor that becomes readable when ``read_many`` has data, or
        ``None`` if this transport cannot be waited on with ``select`` (queue-backed
        ones: python-can's virtual bus, hidapi). The hub serves every device with a
        descriptor from one selector thread instead of one thread each."""
        return None

    @property
    def selectable(self) -> bool:
        """Whether this transport has a descriptor to select on whenever it is connected (its
        class gives ``fileno``), though it may have none now: a device that opened while its
        other end was not ready yet (``DeviceNotReady``) joins the hub's selector once it
        reconnects instead of keeping a thread of its own."""
        return type(self).fileno is not Device.fileno

    def has_buffered(self) -> bool:
        """Whether ``read`` can return a sample without touching the transport."""
        return bool(getattr(self, "_pending", None))

    def __iter__(self) -> Iterator[Sample]:
        """Yield samples until closed; timeouts are skipped."""
        while self._is_open:
            s = self.read(0.5)
            if s is not None:
                yield s

    def _finish(self, sample: Sample, now: float) -> Sample:
        if not sample.t:
            sample.t = now
        self.stats.decoded += 1
        if self._counter is not None and sample.counter is not None:
            lost = self._counter.update(sample.counter)
            if lost:
                self.stats.counter_gaps += 1
                self.stats.lost_packets += lost
                sample.extra["lost_before"] = lost
        return sample

    # --- reconnect --------------------------------------------------------------------------------------
    def _lost(self, exc: BaseException) -> None:
        with self._lock:
            if not self._connected:
                return
            self._connected = False
            self.stats.disconnects += 1
            self._safe_close()
            if self._counter is not None:
                self._counter.reset()
            self._backoff = self.backoff_min
            self._next_attempt = self.clock() + self._backoff
            self._event("disconnected", str(exc))

    def _try_reconnect(self) -> bool:
        with self._lock:
            if self._connected:
                return True
            if not self._is_open:
                return False
            now = self.clock()
            if now < self._next_attempt:
                return False
            try:
                self._open()
            except (OSError, ValueError) as exc:
                self._backoff = min(self.backoff_max, self._backoff * 2)
                self._next_attempt = now + self._backoff
                self._event("reconnect_failed", str(exc))
                return False
            self._connected = True
            self.stats.reconnects += 1
            self._event("reconnected", self.describe())
            return True

    def _safe_close(self) -> None:
        try:
            self._close()
        except OSError:
            pass

    def _event(self, kind: str, detail: str = "") -> None:
        ev = DeviceEvent(self.clock(), self.device_id, kind, detail)
        self.events.append(ev)
        if self.on_event is not None:
            self.on_event(ev)

    # --- backend interface -----------------------------------------------------------------------------
    @abstractmethod
    def _open(self) -> None:
        """Open (or reopen after a loss) the transport and configure the device."""

    @abstractmethod
    def _close(self) -> None:
        """Release the transport. Must tolerate a transport that is already gone."""

    @abstractmethod
    def _read(self, timeout: float | None) -> Sample | None:
        """Return one decoded sample, ``None`` on timeout; raise ``OSError`` on loss."""

    def _read_many(self, timeout: float | None, max_samples: int) -> list[Sample]:
        """Samples available now (waiting up to ``timeout`` for the first), ``[]`` on
        timeout; raise ``OSError`` on loss. The default loops ``_read``, so a backend
        that only overrides ``_read`` works unchanged; stream backends override this
        to decode a whole buffer at once. A loss after the first sample is deferred to
        the next call, so the samples already decoded are not thrown away."""
        s = self._read(timeout)
        if s is None:
            return []
        out = [s]
        while len(out) < max_samples:
            try:
                s = self._read(0.0)
            except OSError as exc:
                self._deferred_loss = exc
                break
            if s is None:
                break
            out.append(s)
        return out
