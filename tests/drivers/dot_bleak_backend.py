"""A stand-in of bleak's *backend* for simulated Movella DOTs: test support.

bleak's ``BleakClient`` and ``BleakScanner`` take a ``backend=`` class (a
``BaseBleakClient`` / ``BaseBleakScanner`` subclass); the platform's is BlueZ over D-Bus,
CoreBluetooth or WinRT. ``dot_backends(folder)`` gives a pair that reaches the DOT twins
of ``sim_devices`` (``SimMovellaDot``) whose sockets are in ``folder`` instead of a radio,
so the driver's real ``BleakSeam`` (its loop thread, bleak's client and scanner above the
backend: characteristic resolution, callback wrapping, the disconnected callback) runs
end to end without Bluetooth.

What the backend does, as a platform backend does it:
- ``connect``: a link to the twin (its socket); a twin that is not there is
  ``BleakDeviceNotFoundError``; then the DOT's GATT table (configuration, measurement and
  battery services with their characteristics and properties) as ``services``.
- ``read_gatt_char`` / ``write_gatt_char`` / ``start_notify``: the twin answers from its
  state with ``drivers.movella_dot.protocol``'s ``encode_*`` functions and notifies the
  payload characteristic with ``encode``; notifications are delivered on the event loop.
- A link the twin drops (``SimMovellaDot.disconnect(seconds)`` or a ``disconnects`` fault)
  calls the disconnected callback on the loop, once; a ``disconnect`` asked for by the host
  does not (bleak calls it on unsolicited disconnects only). After the twin is back, a new
  ``connect`` is accepted.
- ``start`` of the scanner: one advertisement per twin in range (name, Xsens' company id,
  RSSI), through ``create_or_update_device`` and the detection callbacks.

It lives in tests/ and not in sim_devices/: it is a test double of a third-party library's
interface, not a device that speaks one of our wire formats (the twin it reaches does that).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bleak.backends.characteristic import BleakGATTCharacteristic
from bleak.backends.client import BaseBleakClient, NotifyCallback
from bleak.backends.device import BLEDevice
from bleak.backends.scanner import AdvertisementData, BaseBleakScanner
from bleak.backends.service import BleakGATTService, BleakGATTServiceCollection
from bleak.exc import BleakDeviceNotFoundError, BleakError

from drivers.base import DeviceGone
from drivers.movella_dot import protocol as dot
from drivers.movella_dot.ble_seam import SocketLink, SocketSeam, socket_name

# the DOT's GATT table as the driver uses it: service -> [(characteristic, properties)]
GATT: dict[str, list[tuple[str, list[str]]]] = {
    dot.CONFIG_SERVICE: [(dot.DEVICE_INFO, ["read"]), (dot.DEVICE_CONTROL, ["read", "write"])],
    dot.MEASUREMENT_SERVICE: [(dot.CONTROL, ["read", "write"]), (dot.LONG_PAYLOAD, ["notify"]),
                              (dot.MEDIUM_PAYLOAD, ["notify"]), (dot.SHORT_PAYLOAD, ["notify"])],
    dot.BATTERY_SERVICE: [(dot.BATTERY, ["read", "notify"])],
}
MTU = 247  # what a DOT negotiates with a current central; a 40-byte payload fits either way


def dot_services() -> BleakGATTServiceCollection:
    """The DOT's services and characteristics as a bleak collection (handles as a GATT server numbers them)."""
    coll = BleakGATTServiceCollection()
    handle = 1
    for service_uuid, chars in GATT.items():
        service = BleakGATTService(None, handle, service_uuid)
        coll.add_service(service)
        handle += 1
        for char_uuid, props in chars:
            handle += 1  # the characteristic's declaration, then its value
            coll.add_characteristic(BleakGATTCharacteristic(None, handle, char_uuid, props,  # type: ignore[arg-type]
                                                            lambda: MTU - 3, service))
            handle += 2 if "notify" in props else 1  # a CCCD after a notifying value
    return coll


def dot_backends(folder: str | Path) -> tuple[type[BaseBleakClient], type[BaseBleakScanner]]:
    """(client backend, scanner backend) for the DOT twins whose sockets are in ``folder``;
    pass them to ``BleakSeam(client_backend=..., scanner_backend=...)``."""
    where = Path(folder)

    class SimDotClient(_SimDotClient):
        folder = where
        dropped: list[str] = []  # noqa: RUF012 - per pair: the addresses whose links the twins dropped

    class SimDotScanner(_SimDotScanner):
        folder = where

    return SimDotClient, SimDotScanner


class _SimDotClient(BaseBleakClient):
    folder: Path
    dropped: list[str]

    def __init__(self, address_or_ble_device: BLEDevice | str, *, disconnected_callback: Callable[[], None] | None,
                 timeout: float = 10.0, **kwargs: Any) -> None:
        super().__init__(address_or_ble_device, disconnected_callback=disconnected_callback, timeout=timeout)
        self._link: SocketLink | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._notify: dict[str, NotifyCallback] = {}
        self._busy = asyncio.Lock()  # one request at a time on the link, as ATT allows

    @property
    def name(self) -> str:
        return "Movella DOT"

    @property
    def mtu_size(self) -> int:
        return MTU

    @property
    def is_connected(self) -> bool:
        return self._link is not None

    async def connect(self, pair: bool, **kwargs: Any) -> None:
        self._loop = asyncio.get_running_loop()
        path = str(self.folder / socket_name(self.address))
        try:
            link = await asyncio.to_thread(SocketLink, path, self._lost_from_twin)
        except DeviceGone as exc:
            raise BleakDeviceNotFoundError(self.address, f"Device with address {self.address} was not found: {exc}") \
                from exc
        self._link = link
        self._notify = {}
        self.services = dot_services()

    def _lost_from_twin(self, _reason: str) -> None:
        """The link's reader thread saw the twin go: tell bleak on its loop, as a platform backend does."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._on_lost)

    def _on_lost(self) -> None:
        if self._link is None:  # the host disconnected first: not an unsolicited disconnect
            return
        self._link = None
        self.services = None
        self._notify = {}
        self.dropped.append(self.address)
        if self._disconnected_callback is not None:
            self._disconnected_callback()

    async def disconnect(self) -> None:
        link, self._link = self._link, None
        self.services = None
        self._notify = {}
        if link is not None:
            link.disconnect()  # a closed SocketLink calls no lost callback

    async def pair(self, *args: Any, **kwargs: Any) -> None:
        """A DOT needs no pairing."""

    async def unpair(self) -> None:
        """A DOT needs no pairing."""

    def _require(self) -> SocketLink:
        if self._link is None:
            raise BleakError("Not connected")
        return self._link

    async def _ask(self, fn: Callable[..., Any], *args: Any) -> Any:
        link = self._require()
        async with self._busy:
            try:
                return await asyncio.to_thread(fn, link, *args)
            except DeviceGone as exc:
                raise BleakError(str(exc)) from exc

    async def read_gatt_char(self, characteristic: BleakGATTCharacteristic, *, use_cached: bool = False,
                             **kwargs: Any) -> bytearray:
        return bytearray(await self._ask(SocketLink.read, characteristic.uuid))

    async def write_gatt_char(self, characteristic: BleakGATTCharacteristic, data: Any, response: bool) -> None:
        await self._ask(SocketLink.write, characteristic.uuid, bytes(data))

    async def start_notify(self, characteristic: BleakGATTCharacteristic, callback: NotifyCallback,
                           **kwargs: Any) -> None:
        uuid = characteristic.uuid
        self._notify[uuid] = callback
        loop = asyncio.get_running_loop()

        def deliver(data: bytes) -> None:  # on the link's reader thread
            if not loop.is_closed():
                loop.call_soon_threadsafe(self._deliver, uuid, bytearray(data))

        await self._ask(SocketLink.start_notify, uuid, deliver)

    def _deliver(self, uuid: str, data: bytearray) -> None:
        cb = self._notify.get(uuid)
        if cb is not None and self._link is not None:
            cb(data)

    async def stop_notify(self, characteristic: BleakGATTCharacteristic) -> None:
        self._notify.pop(characteristic.uuid, None)

    async def read_gatt_descriptor(self, descriptor: Any, *, use_cached: bool = False, **kwargs: Any) -> bytearray:
        raise BleakError("the DOT stand-in serves no descriptors")

    async def write_gatt_descriptor(self, descriptor: Any, data: Any) -> None:
        raise BleakError("the DOT stand-in serves no descriptors")


class _SimDotScanner(BaseBleakScanner):
    folder: Path

    def __init__(self, detection_callback: Any, service_uuids: list[str] | None, scanning_mode: str = "active",
                 **kwargs: Any) -> None:
        super().__init__(detection_callback, service_uuids)

    async def start(self) -> None:
        self.seen_devices = {}
        for address, adv in await asyncio.to_thread(self._advertisements):
            device = self.create_or_update_device(address, address, adv.local_name, None, adv)
            self.call_detection_callbacks(device, adv)

    def _advertisements(self) -> list[tuple[str, AdvertisementData]]:
        """One advertisement per twin in range (its socket answers the advertisement request)."""
        # the socket seam's own scan walks the twins' sockets and asks each for its advertisement
        out = []
        for a in SocketSeam(self.folder).scan(1.0):
            adv = AdvertisementData(local_name=a.name, manufacturer_data={dot.XSENS_COMPANY_ID: b""},
                                    service_data={}, service_uuids=[], tx_power=None, rssi=int(a.rssi),
                                    platform_data=())
            out.append((a.address, adv))
        return out

    async def stop(self) -> None:
        """Nothing to stop: the advertisements were taken at start."""
