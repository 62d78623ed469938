"""The thin seam between the DOT driver and Bluetooth LE.

The driver needs six calls: scan, connect, start_notify, write a characteristic, read
one (the battery), disconnect. ``BleakSeam`` is the real one (bleak, the maintained
cross-platform BLE client, its asyncio loop on a thread of its own); ``SocketSeam``
speaks the same calls over local SOCK_SEQPACKET sockets, one per simulated DOT in a
folder (``<address with - for :>.sock``), so a twin in this or another process stands
in for the sensor with the GATT characteristics and notification bytes of the real one.

Messages on a socket: one type byte, then the characteristic's 16-byte UUID, then the
value. Host -> device: ``R`` read, ``W`` write, ``N`` enable notifications, ``A`` (no
UUID) advertisement. Device -> host: ``r``/``w``/``n`` answers (``e`` + text for an
error), ``V`` a notification, ``a`` + JSON {name, address, battery, rssi}.
"""

from __future__ import annotations

import asyncio
import json
import os
import queue
import select
import socket
import threading
import uuid as uuidlib
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from ..base import DeviceGone
from ..extras import need
from . import protocol as dot

Notify = Callable[[bytes], None]
Lost = Callable[[str], None]


@dataclass(frozen=True)
class Advert:
    """A DOT seen in a scan."""

    address: str
    name: str
    battery: float | None = None
    rssi: int | None = None


class BleLink(Protocol):
    def read(self, char: str, timeout: float = 2.0) -> bytes: ...

    def write(self, char: str, data: bytes, timeout: float = 2.0) -> None: ...

    def start_notify(self, char: str, callback: Notify, timeout: float = 2.0) -> None: ...

    def disconnect(self) -> None: ...


class BleSeam(Protocol):
    def scan(self, timeout: float) -> list[Advert]: ...

    def connect(self, address: str, on_lost: Lost, timeout: float) -> BleLink: ...


# --- bleak --------------------------------------------------------------------------------------------
class _Loop:
    """One asyncio loop on a daemon thread for every bleak call of the process (bleak is
    asyncio-only; the driver's reads are blocking calls on the hub's threads)."""

    _lock = threading.Lock()
    _loop: asyncio.AbstractEventLoop | None = None

    @classmethod
    def run(cls, coro: Any, timeout: float) -> Any:
        with cls._lock:
            if cls._loop is None:
                loop = asyncio.new_event_loop()
                threading.Thread(target=loop.run_forever, name="imucap-bleak", daemon=True).start()
                cls._loop = loop
        fut: Future = asyncio.run_coroutine_threadsafe(coro, cls._loop)
        try:
            return fut.result(timeout)
        except TimeoutError as exc:
            fut.cancel()
            raise DeviceGone(f"BLE call timed out after {timeout} s") from exc
        except Exception as exc:  # bleak raises BleakError, dbus and OS errors
            if isinstance(exc, OSError):
                raise
            raise DeviceGone(f"BLE: {exc}") from exc


class BleakLink:
    def __init__(self, client: Any) -> None:
        self._client = client

    def read(self, char: str, timeout: float = 2.0) -> bytes:
        return bytes(_Loop.run(self._client.read_gatt_char(char), timeout))

    def write(self, char: str, data: bytes, timeout: float = 2.0) -> None:
        _Loop.run(self._client.write_gatt_char(char, data, response=True), timeout)

    def start_notify(self, char: str, callback: Notify, timeout: float = 2.0) -> None:
        _Loop.run(self._client.start_notify(char, lambda _c, data: callback(bytes(data))), timeout)

    def disconnect(self) -> None:
        try:
            _Loop.run(self._client.disconnect(), 5.0)
        except OSError:
            pass


class BleakSeam:
    """Bluetooth LE through bleak (BlueZ over D-Bus on Linux, CoreBluetooth, WinRT).

    ``client_backend`` and ``scanner_backend`` go to bleak's ``BleakClient`` and
    ``BleakScanner`` as their ``backend=`` (subclasses of ``bleak.backends.client.BaseBleakClient``
    and ``bleak.backends.scanner.BaseBleakScanner``); ``None``, the default, is the platform's own
    stack. They exist so that this class, its loop thread and bleak above the backend can run
    against a stand-in of the radio (``tests/drivers/dot_bleak_backend.py`` serves simulated DOTs).
    """

    def __init__(self, client_backend: type | None = None, scanner_backend: type | None = None) -> None:
        self.client_backend = client_backend
        self.scanner_backend = scanner_backend

    def scan(self, timeout: float) -> list[Advert]:
        """DOTs advertising in range, from their advertisements alone (no connection)."""
        need("bleak", "a Movella DOT over Bluetooth LE")
        from bleak import BleakScanner

        async def go() -> list[Advert]:
            extra = {"backend": self.scanner_backend} if self.scanner_backend is not None else {}
            found = await BleakScanner.discover(timeout=timeout, return_adv=True, **extra)
            out = []
            for dev, adv in found.values():
                name = adv.local_name or dev.name or ""
                if dot.is_dot_advertisement(name, tuple(adv.manufacturer_data)):
                    out.append(Advert(dev.address, name, None, adv.rssi))
            return out

        return _Loop.run(go(), timeout + 5.0)

    def connect(self, address: str, on_lost: Lost, timeout: float) -> BleLink:
        need("bleak", "a Movella DOT over Bluetooth LE")
        from bleak import BleakClient

        extra = {"backend": self.client_backend} if self.client_backend is not None else {}
        client = BleakClient(address, disconnected_callback=lambda _c: on_lost("BLE link lost"), timeout=timeout,
                             **extra)
        _Loop.run(client.connect(), timeout + 1.0)
        return BleakLink(client)


# --- the socket twin's seam -------------------------------------------------------------------------
def socket_name(address: str) -> str:
    return address.upper().replace(":", "-") + ".sock"


class SocketLink:
    """One connection to a simulated DOT: a reader thread dispatches notifications and
    hands answers to the caller waiting for them."""

    def __init__(self, path: str, on_lost: Lost | None = None) -> None:
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._sock.connect(path)
        except OSError as exc:
            self._sock.close()
            raise DeviceGone(f"no DOT answers at {path}: {exc}") from exc
        self._on_lost = on_lost
        self._answers: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._notify: dict[bytes, Notify] = {}
        self._closed = False
        self._thread = threading.Thread(target=self._reader, name="imucap-ble-socket", daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        reason = "BLE link closed by the device"
        while not self._closed:
            try:
                r, _, _ = select.select([self._sock], [], [], 0.2)
                if not r:
                    continue
                msg = self._sock.recv(512)
            except (OSError, ValueError) as exc:
                reason = f"BLE link lost: {exc}"
                break
            if not msg:
                break
            if msg[:1] == b"V":
                cb = self._notify.get(msg[1:17])
                if cb is not None:
                    cb(msg[17:])
            else:
                self._answers.put(msg)
        if not self._closed:
            self._closed = True
            self._answers.put(b"")
            if self._on_lost is not None:
                self._on_lost(reason)

    def _ask(self, kind: bytes, char: str | None, data: bytes, timeout: float) -> bytes:
        if self._closed:
            raise DeviceGone("BLE link closed")
        key = uuidlib.UUID(char).bytes if char else b""
        try:
            self._sock.send(kind + key + data)
        except OSError as exc:
            raise DeviceGone(f"BLE send failed: {exc}") from exc
        try:
            ans = self._answers.get(timeout=timeout)
        except queue.Empty:
            raise DeviceGone(f"no answer from the DOT in {timeout} s") from None
        if not ans:
            raise DeviceGone("BLE link closed")
        if ans[:1] == b"e":
            raise DeviceGone(f"DOT refused: {ans[1:].decode(errors='replace')}")
        if ans[:1] != kind.lower():
            raise DeviceGone(f"unexpected answer {ans[:1]!r} to {kind!r}")
        return ans[1 + len(key) :]

    def read(self, char: str, timeout: float = 2.0) -> bytes:
        return self._ask(b"R", char, b"", timeout)

    def write(self, char: str, data: bytes, timeout: float = 2.0) -> None:
        self._ask(b"W", char, data, timeout)

    def start_notify(self, char: str, callback: Notify, timeout: float = 2.0) -> None:
        self._notify[uuidlib.UUID(char).bytes] = callback
        self._ask(b"N", char, b"", timeout)

    def advertisement(self, timeout: float = 1.0) -> dict[str, Any]:
        return json.loads(self._ask(b"A", None, b"", timeout) or b"{}")

    def disconnect(self) -> None:
        self._closed = True
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()


class SocketSeam:
    """The seam over the sockets of simulated DOTs in ``folder`` (their 'radio range')."""

    def __init__(self, folder: str | os.PathLike) -> None:
        self.folder = Path(folder)

    def path(self, address: str) -> str:
        return str(self.folder / socket_name(address))

    def scan(self, timeout: float) -> list[Advert]:
        out = []
        for p in sorted(self.folder.glob("*.sock")):
            try:
                link = SocketLink(str(p))
            except DeviceGone:
                continue  # a socket file left by a twin that is gone
            try:
                a = link.advertisement(min(timeout, 1.0))
                out.append(Advert(a["address"], a["name"], a.get("battery"), a.get("rssi")))
            except (DeviceGone, ValueError, KeyError):
                continue
            finally:
                link.disconnect()
        return out

    def connect(self, address: str, on_lost: Lost, timeout: float) -> BleLink:
        return SocketLink(self.path(address), on_lost)


def read_battery(seam: BleSeam, address: str, timeout: float = 5.0) -> float | None:
    """One DOT's battery level over a short connection, on demand (a DOT does not advertise
    it, and a scan connects to none); None when the sensor does not let us connect."""
    try:
        link = seam.connect(address, lambda _r: None, timeout)
    except OSError:
        return None
    try:
        return float(dot.decode_battery(link.read(dot.BATTERY)).level)
    except (OSError, dot.DotError):
        return None
    finally:
        link.disconnect()


def scan(seam: BleSeam | None = None, timeout: float = 5.0) -> list[Advert]:
    """DOTs in range through ``seam`` (bleak by default), from their advertisements: no
    connection is made (a battery level is there when the advertisement carries one;
    ``read_battery`` asks one sensor)."""
    return (seam or BleakSeam()).scan(timeout)
