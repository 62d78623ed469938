"""Simulated twins of every supported device, speaking the drivers' wire formats
over real transports (pty, python-can bus, HID and BLE seam sockets, UDP loopback)."""

from __future__ import annotations

from typing import Any

from inference.signals.site_signals import SiteSignals

from .analytic import spinning_signals
from .base import DeviceFaults, InsoleSource, SignalSource, SimDevice
from .other_twins import SimDualSense, SimMoticon, SimXsensCan
from .serial_twins import SimBno08xRvc, SimXbus
from .wireless_twins import SimMovellaDot, SimXimu3

PROTOCOLS: dict[str, type[SimDevice]] = {
    "xbus": SimXbus,
    "bno08x-rvc": SimBno08xRvc,
    "xsens-can": SimXsensCan,
    "dualsense": SimDualSense,
    "moticon-udp": SimMoticon,
    "movella-dot": SimMovellaDot,
    "ximu3": SimXimu3,
}
INSOLE_PROTOCOLS = ("moticon-udp",)


def make_sim_device(
    protocol: str, signals: SiteSignals, site: str, faults: DeviceFaults | None = None, **kw: Any
) -> SimDevice:
    """A simulated device of ``protocol`` replaying ``site`` of ``signals`` (not started).
    For insoles ``site`` is ignored: they replay the insole channels."""
    try:
        cls = PROTOCOLS[protocol]
    except KeyError:
        raise ValueError(f"unknown protocol {protocol!r} (known: {', '.join(PROTOCOLS)})") from None
    if protocol in INSOLE_PROTOCOLS:
        return cls(InsoleSource(signals), faults=faults, **kw)
    if site not in signals.sites:
        raise ValueError(f"site {site!r} not in the signals ({', '.join(signals.sites)})")
    return cls(SignalSource(signals, site), faults=faults, name=kw.pop("name", site), **kw)


__all__ = [
    "DeviceFaults",
    "INSOLE_PROTOCOLS",
    "InsoleSource",
    "PROTOCOLS",
    "SignalSource",
    "SimBno08xRvc",
    "SimDevice",
    "SimDualSense",
    "SimMoticon",
    "SimMovellaDot",
    "SimXimu3",
    "SimXbus",
    "SimXsensCan",
    "make_sim_device",
    "spinning_signals",
]
