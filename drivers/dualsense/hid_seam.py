"""The thin seam between the DualSense driver and HID.

The driver only needs three calls: read an input report, get a feature report,
close. ``HidapiHandle`` is the real one (hidapi); ``SocketHidHandle`` speaks the
same three calls over a local SOCK_SEQPACKET socket so a simulated controller in
this or another process can stand in for the hardware with identical report
bytes. Message format on the socket: one type byte then the report:
``I`` input report (device -> host), ``F`` + report id (host asks for a feature
report), ``f`` + report (device answers).
"""

from __future__ import annotations

import select
import socket
from collections import deque
from typing import Protocol

from ..base import DeviceGone


class HidHandle(Protocol):
    def read(self, size: int, timeout: float | None) -> bytes: ...

    def get_feature_report(self, report_id: int, size: int) -> bytes: ...

    def close(self) -> None: ...


class HidapiHandle:
    """A real HID device through hidapi (``hid`` module)."""

    def __init__(
        self,
        vendor_id: int,
        product_ids: tuple[int, ...],
        serial: str | None = None,
        path: bytes | None = None,
    ) -> None:
        import hid

        self._dev = hid.device()
        try:
            if path is not None:
                self._dev.open_path(path)
            else:
                last: Exception | None = None
                for pid in product_ids:
                    try:
                        self._dev.open(vendor_id, pid, serial)
                        break
                    except OSError as exc:
                        last = exc
                else:
                    raise last or OSError("no device")
        except OSError as exc:
            raise DeviceGone(f"no DualSense found by hidapi ({exc})") from exc

    def read(self, size: int, timeout: float | None) -> bytes:
        ms = -1 if timeout is None else max(0, int(timeout * 1000))
        try:
            data = self._dev.read(size, ms)
        except (OSError, ValueError) as exc:
            raise DeviceGone(f"HID read failed: {exc}") from exc
        return bytes(data)

    def get_feature_report(self, report_id: int, size: int) -> bytes:
        try:
            return bytes(self._dev.get_feature_report(report_id, size))
        except (OSError, ValueError) as exc:
            raise DeviceGone(f"HID feature report failed: {exc}") from exc

    def close(self) -> None:
        self._dev.close()


class SocketHidHandle:
    """The seam over a local socket (the simulated controller's transport)."""

    def __init__(self, path: str) -> None:
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._sock.connect(path)
        except OSError as exc:
            self._sock.close()
            raise DeviceGone(f"no HID endpoint at {path}: {exc}") from exc
        self._inputs: deque[bytes] = deque()

    def _recv(self, timeout: float | None) -> bytes | None:
        r, _, _ = select.select([self._sock], [], [], timeout)
        if not r:
            return None
        try:
            msg = self._sock.recv(4096)
        except OSError as exc:
            raise DeviceGone(str(exc)) from exc
        if not msg:
            raise DeviceGone("HID endpoint closed")
        return msg

    def read(self, size: int, timeout: float | None) -> bytes:
        if self._inputs:
            return self._inputs.popleft()[:size]
        msg = self._recv(timeout)
        if msg is None:
            return b""
        if msg[:1] == b"I":
            return msg[1 : size + 1]
        return b""  # stray feature answer: ignore

    def get_feature_report(self, report_id: int, size: int) -> bytes:
        try:
            self._sock.send(b"F" + bytes((report_id,)))
        except OSError as exc:
            raise DeviceGone(str(exc)) from exc
        for _ in range(1000):
            msg = self._recv(1.0)
            if msg is None:
                break
            if msg[:1] == b"f":
                return msg[1 : size + 1]
            if msg[:1] == b"I":
                self._inputs.append(msg[1:])
        raise DeviceGone("no answer to feature report request")

    def close(self) -> None:
        self._sock.close()
