"""x-IMU3 live, through x-io's own ``ximu3`` package (its Rust parser, its UDP, TCP and
serial transports): inertial and quaternion messages joined on their timestamps into
samples, battery from the battery message.

Time is the device's microsecond timestamp. The messages carry no packet counter, so
lost samples are inferred from the timestamps, at the period the stream itself shows
(``StreamPeriod``: a grid fitted to the last samples' timestamps, robust to the losses it
counts and to stamps late by part of a period); the URL's ``rate`` is only a first guess,
and no loss is counted from it (the first steps are counted once the stream has shown its
period). Loss of the link: an
x-IMU3 streams without pause, so a stream silent for ``stale`` seconds is a lost link on
every transport (the package's status callback did not report a TCP peer that closed;
UDP has no connection at all); a disconnected status counts too. Reconnecting means
opening the connection again (TCP connects, the serial port opens) and, over UDP, the
device answering a ping on its command port. The base class reconnects with its backoff
and counts it.
"""

from __future__ import annotations

import json
import queue
import time
from collections import deque
from typing import Any

import numpy as np

from .._math import G, quat_rotate
from ..base import Device, DeviceGone, Sample
from ..extras import need

_LOST = ("lost",)
_DEG = np.pi / 180.0


class Ximu3Device(Device):
    """``ximu3://udp/8000?ip=127.0.0.1&send_port=9000`` (receive on 8000, commands to the
    device at ip:send_port; send_port defaults to PORT+1000), ``ximu3://tcp/HOST:PORT``,
    ``ximu3://serial/dev/ttyACM0?baud=115200``. ``rate`` (Hz, default 100) is a hint of the
    rate the device sends at (the loss count measures it from the stream); ``stale`` (s,
    default 1.0) how long the stream may be silent before it counts as lost."""

    scheme = "ximu3"

    def __init__(self, transport: str, config: dict[str, Any], *, rate: float = 100.0, stale: float = 1.0,
                 ping_timeout: float = 0.3, **kw: Any) -> None:
        super().__init__(kw.pop("device_id", None) or f"ximu3-{transport}", **kw)
        if transport not in ("udp", "tcp", "serial"):
            raise ValueError(f"ximu3 transport {transport!r}: udp, tcp or serial")
        self.transport, self.config = transport, config
        self.rate, self.stale, self.ping_timeout = rate, stale, ping_timeout
        self.battery: float | None = None
        self.device_name: str | None = None
        self._conn: Any = None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._last_i: tuple[int, np.ndarray, np.ndarray] | None = None
        self._held_q: tuple[int, np.ndarray] | None = None
        self._last_ts: int | None = None
        self._period = StreamPeriod()
        self._last_msg = 0.0
        self._ready: deque[Sample] = deque()

    @classmethod
    def from_url(cls, netloc: str, path: str, params: dict[str, str], **kw: Any) -> Ximu3Device:
        rest = path.lstrip("/")
        cfg: dict[str, Any]
        if netloc == "udp":
            if not rest.isdigit():
                raise ValueError(f"ximu3://udp/PORT needs the port the device sends to, not {rest!r}")
            port = int(rest)
            cfg = {"ip": params.get("ip", "127.0.0.1"), "receive_port": port,
                   "send_port": int(params.get("send_port", port + 1000))}
        elif netloc == "tcp":
            host, _, port_s = rest.rpartition(":")
            if not host or not port_s.isdigit():
                raise ValueError(f"ximu3://tcp/HOST:PORT needs host and port, not {rest!r}")
            cfg = {"ip": host, "port": int(port_s)}
        elif netloc == "serial":
            if not rest:
                raise ValueError("ximu3://serial/PATH needs the serial port's path")
            cfg = {"port": "/" + rest, "baud": int(params.get("baud", 115200)),
                   "rts_cts": params.get("rts_cts", "0") in ("1", "true", "on")}
        else:
            raise ValueError(f"ximu3 URL is ximu3://udp/PORT, ximu3://tcp/HOST:PORT or ximu3://serial/PATH, "
                             f"not ximu3://{netloc}/...")
        try:
            rate, stale = float(params.get("rate", 100.0)), float(params.get("stale", 1.0))
        except ValueError:
            raise ValueError("ximu3 URL: rate and stale are numbers") from None
        need("ximu3", "an x-IMU3 (ximu3://)")
        return cls(netloc, cfg, rate=rate, stale=stale, **kw)

    def describe(self) -> str:
        c = self.config
        if self.transport == "udp":
            return f"ximu3://udp/{c['receive_port']}?ip={c['ip']}&send_port={c['send_port']}"
        if self.transport == "tcp":
            return f"ximu3://tcp/{c['ip']}:{c['port']}"
        return f"ximu3://serial{c['port']}"

    def _connection_config(self) -> Any:
        import ximu3

        c = self.config
        if self.transport == "udp":
            return ximu3.UdpConnectionConfig(c["ip"], c["send_port"], c["receive_port"])
        if self.transport == "tcp":
            return ximu3.TcpConnectionConfig(c["ip"], c["port"])
        return ximu3.SerialConnectionConfig(c["port"], c["baud"], c["rts_cts"])

    # --- transport ---------------------------------------------------------------------------------
    def _open(self) -> None:
        import ximu3

        q: queue.SimpleQueue = queue.SimpleQueue()
        conn = ximu3.Connection(self._connection_config())
        conn.add_inertial_callback(lambda m: q.put(("I", m.timestamp, (m.gyroscope_x, m.gyroscope_y, m.gyroscope_z),
                                                    (m.accelerometer_x, m.accelerometer_y, m.accelerometer_z))))
        conn.add_quaternion_callback(lambda m: q.put(("Q", m.timestamp, (m.w, m.x, m.y, m.z))))
        conn.add_battery_callback(lambda m: q.put(("B", m.timestamp, m.percentage)))
        conn.add_receive_error_callback(lambda _e: q.put(("E",)))
        conn.add_status_callback(lambda s: q.put(_LOST) if s == ximu3.CONNECTION_STATUS_DISCONNECTED else None)
        try:
            conn.open()
        except RuntimeError as exc:  # the package reports refused connections and missing ports so
            raise DeviceGone(f"{self.describe()}: {exc}") from exc
        answer = conn.send_command('{"ping":null}', 0, int(self.ping_timeout * 1000))
        if answer is None and self.transport == "udp":
            conn.close()
            raise DeviceGone(f"{self.describe()}: no x-IMU3 answered a ping")
        if answer is not None:
            self.device_name = _ping_name(answer.json)
        self._conn, self._queue = conn, q
        self._last_i = self._held_q = None
        self._ready.clear()
        self._last_ts = None
        self._period = StreamPeriod()
        self._last_msg = time.monotonic()

    def _close(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()

    def _read(self, timeout: float | None) -> Sample | None:
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._ready:
                return self._ready.popleft()
            if self._conn is None:
                raise DeviceGone("connection closed")
            now = time.monotonic()
            if now - self._last_msg > self.stale:
                raise DeviceGone(f"no x-IMU3 messages for {self.stale:g} s")
            wait = None if end is None else max(0.0, end - now)
            wait = self.stale if wait is None else min(wait, self.stale)
            try:
                item = self._queue.get(timeout=wait) if wait > 0 else self._queue.get_nowait()
            except queue.Empty:
                if end is not None and time.monotonic() >= end:
                    return None
                continue
            if item is _LOST:
                raise DeviceGone("x-IMU3 connection lost")
            self._last_msg = time.monotonic()
            sample = self._handle(item)
            if sample is not None:
                return sample
            if end is not None and time.monotonic() >= end and self._queue.empty():
                return None

    def has_buffered(self) -> bool:
        return bool(self._ready) or not self._queue.empty()

    def _handle(self, item: tuple) -> Sample | None:
        kind = item[0]
        if kind == "E":
            self.stats.bad_frame += 1
            return None
        if kind == "B":
            self.battery = float(item[2])
            return None
        if kind == "I":
            ts = int(item[1])
            self._last_i = (ts, np.radians(np.asarray(item[2], float)), np.asarray(item[3], float) * G)
            if self._held_q is not None and self._held_q[0] == ts:
                held, self._held_q = self._held_q, None
                return self._sample(*held)
            return None
        # a quaternion: paired with the inertial message of the same timestamp, whichever comes first
        ts, quat = int(item[1]), np.asarray(item[2], float)
        n = float(np.linalg.norm(quat))
        if not 0.5 < n < 1.5:
            self.stats.bad_frame += 1
            return None
        quat = quat / n
        held, self._held_q = self._held_q, None
        out = None if held is None else self._sample(*held)  # its inertial never came (lost, or a lower rate)
        if self._last_i is not None and self._last_i[0] == ts:
            now = self._sample(ts, quat)
            if out is None:
                return now
            self._ready.append(now)
            return out
        self._held_q = (ts, quat)
        return out

    def _sample(self, ts: int, quat: np.ndarray) -> Sample:
        extra: dict[str, Any] = {}
        gaps, missing = self._period.add(ts)
        if gaps:
            self.stats.counter_gaps += gaps
            self.stats.lost_packets += missing
            extra["lost_before"] = missing
        self._last_ts = ts
        acc = gyro = free = None
        i = self._last_i
        period_us = self._period.period_us or 1e6 / self.rate
        if i is not None and abs(i[0] - ts) < period_us:
            gyro, acc = i[1], i[2]
            free = quat_rotate(quat, acc) - np.array([0.0, 0.0, G])
        return Sample(0.0, ts * 1e-6, self.device_id, None, quat=quat, free_acc=free, acc=acc, gyro=gyro,
                      battery=self.battery, extra=extra)


class StreamPeriod:
    """A stream's sample period from its own timestamps, and the samples missing before each.

    Each sample gets an index on the stream's grid: the timestamp's distance from where the
    grid puts the last sample, in periods, rounded (at least 1; ``missing`` = the index step
    - 1). The grid is the least-squares line through the last ``window`` samples' indices
    and timestamps (its slope the period), so it is not moved by a lost sample, and a
    timestamp late or early by a fraction of a period (a device that stamps when it sends,
    not when it samples) is still its own index. The first ``first`` timestamps are held until
    the median of their steps gives a first period, then counted. When the median step of
    the window leaves the period by a quarter (the device set to another rate), the grid
    starts again from the newest steps."""

    def __init__(self, window: int = 64, first: int = 9) -> None:
        self.window, self.first = window, first
        self._held: list[int] = []
        self._idx: deque[int] = deque(maxlen=window)
        self._ts: deque[int] = deque(maxlen=window)
        self._steps: deque[int] = deque(maxlen=window)
        self.period_us: float | None = None

    def add(self, ts_us: int) -> tuple[int, int]:
        """(gaps, samples missing) before the sample stamped ``ts_us`` (and those held till now)."""
        last = self._ts[-1] if self._ts else (self._held[-1] if self._held else None)
        if last is not None and ts_us <= last:
            return 0, 0  # a repeated or reordered timestamp: no step of the stream
        if last is not None:
            self._steps.append(ts_us - last)
        if self.period_us is None:
            self._held.append(ts_us)
            if len(self._held) < self.first:
                return 0, 0
            return self._restart(self._held)
        median = float(np.median(self._steps))
        if abs(median - self.period_us) > 0.25 * self.period_us:
            self._restart(list(self._ts)[-self.first:])  # counted already: only the new sample is counted
        return self._place(ts_us)

    def _restart(self, stamps: list[int]) -> tuple[int, int]:
        steps = np.diff(stamps)
        self.period_us = float(np.median(steps))
        self._held = []
        self._idx.clear()
        self._ts.clear()
        self._idx.append(0)
        self._ts.append(stamps[0])
        gaps = missing = 0
        for ts in stamps[1:]:
            g, m = self._place(ts)
            gaps, missing = gaps + g, missing + m
        return gaps, missing

    def _place(self, ts: int) -> tuple[int, int]:
        p = self.period_us
        idx, t = np.asarray(self._idx, float), np.asarray(self._ts, float)
        if len(idx) >= 8:
            di = idx - idx.mean()
            p = self.period_us = float(np.dot(di, t - t.mean()) / np.dot(di, di))
        grid_last = float(np.mean(t - idx * p)) + idx[-1] * p  # where the grid puts the last sample
        k = max(1, round((ts - grid_last) / p))
        self._idx.append(self._idx[-1] + k)
        self._ts.append(ts)
        return (1, k - 1) if k > 1 else (0, 0)


def _ping_name(text: str) -> str | None:
    try:
        ping = json.loads(text).get("ping") or {}
    except (ValueError, AttributeError):
        return None
    return ping.get("device_name") or ping.get("deviceName") if isinstance(ping, dict) else None
