"""Real devices and their wire formats. Imports nothing else of imucap.

``open_device(url)`` picks the backend from the URL scheme (DESIGN.md):

- ``xbus:///dev/ttyUSB0?baud=115200&rate=100&precision=float32&frame=enu``
- ``bno08x-rvc:///dev/ttyUSB1``
- ``xsens-can://<python-can interface>/<channel>?id_offset=0x100&bitrate=1000000``
- ``dualsense://`` (hidapi; ``?serial=``), ``dualsense://unix/<socket>`` (simulated)
- ``moticon-udp://127.0.0.1:9999?weight_kg=75``
- ``movella-dot://D4:22:CD:00:01:27`` (bleak; ``?ble=DIR`` a simulated DOT's socket folder)
- ``ximu3://udp/8000?ip=...&send_port=9000``, ``ximu3://tcp/HOST:PORT``, ``ximu3://serial/PATH``
- ``vmc-in://127.0.0.1:39540?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL`` (VR devices as VMC
  protocol device messages; one device, several sites: ``drivers/vmc/device.py``)

Every URL accepts ``id=<name>`` (the device id samples carry) and
``reconnect=0`` to turn the automatic reconnect off.
"""

from __future__ import annotations

from typing import Any

from .base import CounterTracker, Device, DeviceEvent, DeviceGone, DeviceNotReady, DeviceStats, Sample, Unwrapper
from .urls import DeviceURL, build_url, parse_url

SCHEMES = ("xbus", "bno08x-rvc", "xsens-can", "dualsense", "moticon-udp", "movella-dot", "ximu3", "vmc-in")


def make_device(url: str, **kw: Any) -> Device:
    """The device object for ``url``, not yet opened."""
    u = parse_url(url)
    common: dict[str, Any] = {"reconnect": u.get_bool("reconnect", True)}
    if u.get("id"):
        common["device_id"] = u.get("id")
    common.update(kw)
    if u.scheme == "xbus":
        from .xbus.driver import XbusDevice

        return XbusDevice(
            _port(u),
            u.get_int("baud", 115200),
            rate=u.get_int("rate", 100),
            precision=u.get("precision", "float32") or "float32",
            frame=u.get("frame", "enu") or "enu",
            configure=u.get_bool("configure", True),
            **common,
        )
    if u.scheme == "bno08x-rvc":
        from .bno08x.driver import Bno08xRvcDevice

        return Bno08xRvcDevice(_port(u), u.get_int("baud", 115200), **common)
    if u.scheme == "xsens-can":
        from .xsens_can.driver import XsensCanDevice

        channel = u.path.lstrip("/")
        if not u.netloc or not channel:
            raise ValueError(f"xsens-can URL needs interface and channel: {url!r}")
        bitrate = u.get_int("bitrate", 0) or None
        return XsensCanDevice(u.netloc, channel, id_offset=u.get_int("id_offset", 0), bitrate=bitrate, **common)
    if u.scheme == "dualsense":
        from .dualsense.driver import DualSenseDevice

        return DualSenseDevice.from_url(u.netloc, u.path, u.params, **common)
    if u.scheme == "moticon-udp":
        from .moticon.driver import MoticonUdpDevice

        host, _, port = u.netloc.rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"moticon-udp URL needs host:port: {url!r}")
        return MoticonUdpDevice(
            host,
            int(port),
            weight_kg=u.get_float("weight_kg", 75.0),
            rate=u.get_float("rate", 100.0),
            **common,
        )
    if u.scheme == "movella-dot":
        from .movella_dot.driver import MovellaDotDevice

        return MovellaDotDevice.from_url(u.netloc, u.params, **common)
    if u.scheme == "ximu3":
        from .ximu3.driver import Ximu3Device

        return Ximu3Device.from_url(u.netloc, u.path, u.params, **common)
    if u.scheme == "vmc-in":
        from .vmc.device import VmcInDevice

        return VmcInDevice.from_url(u.netloc, u.params, **common)
    raise ValueError(f"unknown device scheme {u.scheme!r} (known: {', '.join(SCHEMES)})")


def open_device(url: str, **kw: Any) -> Device:
    """Open the device at ``url`` (the object ``imucap devices probe`` uses)."""
    return make_device(url, **kw).open()


def _port(u: DeviceURL) -> str:
    port = (u.netloc + u.path) if u.netloc else u.path
    if not port:
        raise ValueError(f"{u.scheme} URL names no port")
    return port


__all__ = [
    "CounterTracker",
    "Device",
    "DeviceEvent",
    "DeviceGone",
    "DeviceNotReady",
    "DeviceStats",
    "DeviceURL",
    "SCHEMES",
    "Sample",
    "Unwrapper",
    "build_url",
    "make_device",
    "open_device",
    "parse_url",
]
