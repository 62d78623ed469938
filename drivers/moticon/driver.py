"""Moticon OpenGo insoles: the UDP stream of both insoles as one device."""

from __future__ import annotations

import select
import socket
from typing import Any

import numpy as np

from .._math import G
from ..base import Device, DeviceGone, Sample
from . import protocol as mot


class MoticonUdpDevice(Device):
    """``moticon-udp://127.0.0.1:9999?weight_kg=75&rate=100`` binds that address
    and receives the OpenGo stream.

    UDP carries no packet counter, so lost datagrams are inferred from the
    stream's own time column: a step longer than 1.5 nominal periods counts the
    missing periods as lost packets."""

    scheme = "moticon-udp"
    kind = "insoles"

    def __init__(self, host: str, port: int, *, weight_kg: float = 75.0, rate: float = 100.0, **kw: Any) -> None:
        super().__init__(kw.pop("device_id", None) or "insoles", **kw)
        self.host, self.port = host, port
        self.rate = rate
        self.weight_kg = weight_kg
        self.detector = mot.ContactDetector(weight_kg * G)
        self._sock: socket.socket | None = None
        self._last_time: float | None = None

    def describe(self) -> str:
        return f"moticon-udp://{self.host}:{self.port}"

    def _open(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self.host, self.port))
        except OSError as exc:
            s.close()
            raise DeviceGone(f"cannot bind {self.host}:{self.port}: {exc}") from exc
        if self.port == 0:
            self.port = s.getsockname()[1]
        self._sock = s
        self._last_time = None

    def _close(self) -> None:
        s, self._sock = self._sock, None
        if s is not None:
            s.close()

    def _read(self, timeout: float | None) -> Sample | None:
        if self._sock is None:
            raise DeviceGone("socket closed")
        r, _, _ = select.select([self._sock], [], [], timeout)
        if not r:
            return None
        data = self._sock.recv(65536)
        try:
            f = mot.decode(data)
        except mot.MoticonError:
            self.stats.bad_frame += 1
            return None
        return self._to_sample(f)

    def _read_many(self, timeout: float | None, max_samples: int) -> list[Sample]:
        """Every datagram queued on the socket: one select, then non-blocking
        receives until the socket is empty."""
        sock = self._sock
        if sock is None:
            raise DeviceGone("socket closed")
        r, _, _ = select.select([sock], [], [], timeout)
        if not r:
            return []
        out: list[Sample] = []
        while len(out) < max_samples:
            try:
                data = sock.recv(65536, socket.MSG_DONTWAIT)
            except BlockingIOError:
                break
            try:
                f = mot.decode(data)
            except mot.MoticonError:
                self.stats.bad_frame += 1
                continue
            out.append(self._to_sample(f))
        return out

    def fileno(self) -> int | None:
        s = self._sock
        return None if s is None or not self._connected else s.fileno()

    def _to_sample(self, f: mot.InsoleFrame) -> Sample:
        extra: dict[str, Any] = {}
        if self._last_time is not None:
            missing = round((f.time - self._last_time) * self.rate) - 1
            if missing > 0 and (f.time - self._last_time) * self.rate > 1.5:
                self.stats.counter_gaps += 1
                self.stats.lost_packets += missing
                extra["lost_before"] = missing
        self._last_time = f.time
        contacts = self.detector.update(f.time, f.total_force, f.cop)
        extra.update(
            force=f.total_force.copy(),
            contacts=contacts,
            cop=f.cop.copy(),
            pressure=f.pressure.copy(),
            foot_acc=f.acc_g * G,
            foot_gyro=np.radians(f.gyro_dps),
        )
        return Sample(0.0, f.time, self.device_id, None, extra=extra)
