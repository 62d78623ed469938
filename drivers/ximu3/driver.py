"""x-IMU3 live, through x-io's own ``ximu3`` package (its Rust parser, its UDP, TCP and
serial transports): inertial and quaternion messages joined on their timestamps into
samples, battery from the battery message.

Time is the device's microsecond timestamp. The messages carry no packet counter, so
lost samples are inferred from the timestamps at the URL's ``rate``. Loss of the link: an
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

_LOST = ("lost",)
_DEG = np.pi / 180.0


class Ximu3Device(Device):
    """``ximu3://udp/8000?ip=127.0.0.1&send_port=9000`` (receive on 8000, commands to the
    device at ip:send_port; send_port defaults to PORT+1000), ``ximu3://tcp/HOST:PORT``,
    ``ximu3://serial/dev/ttyACM0?baud=115200``. ``rate`` (Hz, default 100) is the rate the
    device was set to send at, for the loss count; ``stale`` (s, default 1.0) how long the
    stream may be silent before it counts as lost."""

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
        if self._last_ts is not None:
            step = (ts - self._last_ts) * 1e-6 * self.rate
            if step > 1.5:
                missing = round(step) - 1
                self.stats.counter_gaps += 1
                self.stats.lost_packets += missing
                extra["lost_before"] = missing
        self._last_ts = ts
        acc = gyro = free = None
        i = self._last_i
        if i is not None and abs(i[0] - ts) * 1e-6 * self.rate < 1.0:
            gyro, acc = i[1], i[2]
            free = quat_rotate(quat, acc) - np.array([0.0, 0.0, G])
        return Sample(0.0, ts * 1e-6, self.device_id, None, quat=quat, free_acc=free, acc=acc, gyro=gyro,
                      battery=self.battery, extra=extra)


def _ping_name(text: str) -> str | None:
    try:
        ping = json.loads(text).get("ping") or {}
    except (ValueError, AttributeError):
        return None
    return ping.get("device_name") or ping.get("deviceName") if isinstance(ping, dict) else None
