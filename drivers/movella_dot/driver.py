"""Movella DOT: real-time streaming over Bluetooth LE, in payload mode 3 (complete
quaternion: orientation and free acceleration in one notification).

Time is the sensor's own: the notification's microsecond timestamp, unwrapped, is the
sample's ``device_time``; the hub fits each device clock to the host's. BLE carries no
packet counter, so lost notifications are inferred from the timestamps: a step longer
than 1.5 sample periods counts the missing periods (``lost_before``), as the Moticon
UDP stream does.

Several DOTs: each one's clock is its own crystal (tens of ppm apart, offsets of
seconds); the DOT's own synchronisation (a message-service exchange run by the DOT
app/SDK before recording) is not implemented. The hub's per-device clock fit maps every
sensor onto the host clock instead; what is left is the BLE delivery jitter the fit
cannot see through (a notification waits for the next connection event, 7.5-30 ms).
docs/devices.md gives the measured figure.
"""

from __future__ import annotations

import queue
from typing import Any

import numpy as np

from ..base import Device, DeviceGone, Sample, Unwrapper
from ..extras import need
from . import protocol as dot
from .ble_seam import BleakSeam, BleLink, BleSeam, SocketSeam

_LOST = b""  # queue marker: the link went away


class MovellaDotDevice(Device):
    """``movella-dot://D4:22:CD:00:01:27`` (bleak; on macOS the CoreBluetooth UUID a scan lists,
    ``movella-dot://6E400001-B5A3-F393-E0A9-E50E24DCCA9E``), ``?ble=DIR`` for a simulated DOT whose
    socket is in DIR, ``?rate=60`` the output rate asked for (1-120 Hz, the DOT's list),
    ``?mode=3`` the payload mode (2 or 3: both carry orientation and free acceleration).
    ``seam=`` (a keyword of ``drivers.make_device``/``open_device``, not of the URL) hands in the
    seam to use instead, e.g. a ``BleakSeam`` over another bleak backend."""

    scheme = "movella-dot"

    def __init__(
        self,
        address: str,
        seam: BleSeam,
        *,
        rate: int = 60,
        mode: int = dot.MODE_COMPLETE_QUATERNION,
        connect_timeout: float = 10.0,
        **kw: Any,
    ) -> None:
        super().__init__(kw.pop("device_id", None) or address, **kw)
        if rate not in dot.OUTPUT_RATES:
            raise ValueError(f"movella-dot rate={rate}: the DOT streams at {', '.join(map(str, dot.OUTPUT_RATES))} Hz")
        if mode not in (dot.MODE_COMPLETE_QUATERNION, dot.MODE_EXTENDED_QUATERNION):
            raise ValueError(f"movella-dot mode={mode}: 2 or 3 (the modes with orientation and free acceleration)")
        self.address = address.upper()
        self.seam = seam
        self.rate = rate
        self.mode = mode
        self.connect_timeout = connect_timeout
        self.battery: float | None = None
        self._link: BleLink | None = None
        self._queue: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._unwrap = Unwrapper(dot.TIMESTAMP_MOD, 1e-6)
        self._last_t: float | None = None
        self._gen = 0  # link generation: notifications of a closed link are dropped

    @classmethod
    def from_url(cls, netloc: str, params: dict[str, str], **kw: Any) -> MovellaDotDevice:
        address = netloc.upper()
        if not is_ble_address(address):
            raise ValueError(f"movella-dot URL needs the sensor's Bluetooth address (AA:BB:CC:DD:EE:FF, or on macOS "
                             f"the CoreBluetooth UUID 8-4-4-4-12 hex digits that a scan lists), not {netloc!r}")
        folder = params.get("ble")
        seam: BleSeam | None = kw.pop("seam", None)
        if seam is None:
            if not folder:
                need("bleak", "a Movella DOT over Bluetooth LE (movella-dot://)")
            seam = SocketSeam(folder) if folder else BleakSeam()
        try:
            rate, mode = int(params.get("rate", 60)), int(params.get("mode", dot.MODE_COMPLETE_QUATERNION))
        except ValueError as exc:
            raise ValueError(f"movella-dot URL: rate and mode are integers ({exc})") from None
        return cls(address, seam, rate=rate, mode=mode, **kw)

    def describe(self) -> str:
        where = f"?ble={self.seam.folder}" if isinstance(self.seam, SocketSeam) else ""
        return f"movella-dot://{self.address}{where}"

    # --- transport ---------------------------------------------------------------------------------
    def _open(self) -> None:
        self._gen += 1
        gen = self._gen
        self._queue = q = queue.SimpleQueue()

        def lost(_reason: str) -> None:
            q.put(_LOST)

        def notified(data: bytes) -> None:
            if gen == self._gen:
                q.put(data)

        link = self.seam.connect(self.address, lost, self.connect_timeout)
        try:
            self._read_battery(link)
            control = self._device_control(link)
            if control is not None and int.from_bytes(control[24:26], "little") != self.rate:
                link.write(dot.DEVICE_CONTROL, _with_rate(control, self.rate))
            link.start_notify(dot.characteristic_for(self.mode), notified)
            link.start_notify(dot.BATTERY, self._on_battery)
            link.write(dot.CONTROL, dot.encode_control(dot.DotControl(action=1, payload_mode=self.mode)))
        except BaseException:
            link.disconnect()
            raise
        self._link = link
        self._unwrap.reset()
        self._last_t = None

    def _read_battery(self, link: BleLink) -> None:
        try:
            self.battery = float(dot.decode_battery(link.read(dot.BATTERY)).level)
        except dot.DotError:
            self.stats.bad_frame += 1

    def _device_control(self, link: BleLink) -> bytes | None:
        try:
            data = link.read(dot.DEVICE_CONTROL)
        except DeviceGone:
            return None
        return data if len(data) >= 26 else None

    def _on_battery(self, data: bytes) -> None:
        try:
            self.battery = float(dot.decode_battery(data).level)
        except dot.DotError:
            self.stats.bad_frame += 1

    def _close(self) -> None:
        link, self._link = self._link, None
        self._gen += 1
        if link is None:
            return
        try:
            link.write(dot.CONTROL, dot.encode_control(dot.DotControl(action=0, payload_mode=self.mode)), 0.5)
        except OSError:
            pass
        link.disconnect()

    def _read(self, timeout: float | None) -> Sample | None:
        if self._link is None:
            raise DeviceGone("BLE link closed")
        try:
            data = self._queue.get(timeout=timeout) if timeout != 0.0 else self._queue.get_nowait()
        except queue.Empty:
            return None
        if data is _LOST or not data:
            raise DeviceGone("BLE link lost")
        try:
            m = dot.decode(data, self.mode)
        except dot.DotError:
            self.stats.bad_frame += 1
            return None
        return self._to_sample(m)

    def has_buffered(self) -> bool:
        return not self._queue.empty()

    def _to_sample(self, m: dot.DotMeasurement) -> Sample:
        t = self._unwrap.update(m.timestamp_us)
        extra: dict[str, Any] = {}
        if self._last_t is not None:
            step = (t - self._last_t) * self.rate
            if step > 1.5:
                missing = round(step) - 1
                self.stats.counter_gaps += 1
                self.stats.lost_packets += missing
                extra["lost_before"] = missing
        self._last_t = t
        quat = np.array(m.quat, dtype=float)
        quat /= np.linalg.norm(quat)
        return Sample(0.0, t, self.device_id, None, quat=quat, free_acc=np.array(m.free_acc, dtype=float),
                      battery=self.battery, status=m.status, extra=extra)


def is_ble_address(address: str) -> bool:
    """A MAC address (BlueZ, Windows) or a CoreBluetooth device UUID (macOS: bleak names a
    sensor by the UUID the system gives it, never by its MAC)."""
    hexdigits = set("0123456789ABCDEFabcdef")
    parts = address.split(":")
    if len(parts) == 6 and all(len(p) == 2 and set(p) <= hexdigits for p in parts):
        return True
    groups = address.split("-")
    return [len(g) for g in groups] == [8, 4, 4, 4, 12] and all(set(g) <= hexdigits for g in groups)


def _with_rate(control: bytes, rate: int) -> bytes:
    """The device control characteristic rewritten to set the output rate (visit index
    0x10 says which field the write changes)."""
    b = bytearray(control)
    b[0] = 0x10
    b[24:26] = rate.to_bytes(2, "little")
    return bytes(b)


def list_dots(seam: BleSeam | None = None, timeout: float = 5.0) -> list[dict[str, Any]]:
    """DOTs in range for ``imucap devices list``: name, address, battery and the URL."""
    from .ble_seam import scan

    out = []
    for a in scan(seam, timeout):
        url = f"movella-dot://{a.address}"
        if isinstance(seam, SocketSeam):
            url += f"?ble={seam.folder}"
        out.append({"kind": "ble", "path": a.address, "what": a.name, "battery": a.battery, "rssi": a.rssi,
                    "url": url})
    return out


__all__ = ["MovellaDotDevice", "list_dots"]
