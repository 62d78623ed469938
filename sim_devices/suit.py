"""A simulated suit: one simulated device per assigned site, each speaking its
protocol over its real transport, all replaying one set of synthesized signals.

Signal-side imperfections (noise, bias, mounting rotation, heading offset) are
applied by ``inference.synthesis.synthesize`` with its ``NoiseModel``; device-
side ones (loss bursts, corrupted bytes, disconnects, clock offset and drift)
by ``DeviceFaults`` here.
"""

from __future__ import annotations

import tempfile
import uuid
from dataclasses import dataclass
from typing import Any

from inference.signals.site_signals import SiteSignals

from .devices import INSOLE_PROTOCOLS, DeviceFaults, SimDevice, make_sim_device
from .devices.can_loopback import REMOTE_INTERFACE, loopback_channel

INSOLES = "insoles"


@dataclass
class SuitDevice:
    site: str
    protocol: str
    sim: SimDevice

    @property
    def url(self) -> str:
        return self.sim.url


class SimulatedSuit:
    """``assignment`` maps site -> protocol (``{"pelvis": "xbus", "insoles": "moticon-udp"}``).

    CAN devices share one bus, each moved to its own identifier block (0x100 per
    sensor), as several MTi-600 on one real bus are configured. The bus is python-can's
    in-process ``virtual`` one, or with ``can_interface="remote"`` one served on loopback
    for another process (``can_channel`` HOST:PORT; a free port when left out). Every device gets
    a different clock offset and drift, so the hub's clock fit is exercised.
    """

    def __init__(
        self,
        signals: SiteSignals,
        assignment: dict[str, str],
        faults: DeviceFaults | dict[str, DeviceFaults] | None = None,
        seed: int = 0,
        can_interface: str = "virtual",
        can_channel: str | None = None,
    ) -> None:
        self.signals = signals
        self.devices: dict[str, SuitDevice] = {}
        if can_interface == REMOTE_INTERFACE:
            channel = loopback_channel(can_channel)  # one server, one port, for the suit's MTis
        else:
            channel = can_channel or f"imucap-suit-{uuid.uuid4().hex[:8]}"
        ble_folder: str | None = None  # the suit's DOTs share one 'radio range' (a scan lists them all)
        n_can = 0
        for k, (site, protocol) in enumerate(assignment.items()):
            f = faults.get(site) if isinstance(faults, dict) else faults
            if f is None:
                f = DeviceFaults(clock_offset=100.0 * (k + 1), drift_ppm=(-1) ** k * 20.0 * (k + 1), seed=seed + k)
            kw: dict[str, Any] = {}
            if protocol == "xsens-can":
                kw.update(interface=can_interface, channel=channel, id_offset=0x100 * n_can)
                n_can += 1
            if protocol == "movella-dot":
                ble_folder = ble_folder or tempfile.mkdtemp(prefix="imucap-ble-")
                kw.update(folder=ble_folder)
            if protocol in INSOLE_PROTOCOLS and site != INSOLES:
                raise ValueError(f"insoles are assigned as {INSOLES!r}, not {site!r}")
            name = site if protocol not in INSOLE_PROTOCOLS else INSOLES
            sim = make_sim_device(protocol, signals, site, faults=f, name=name, **kw)
            self.devices[site] = SuitDevice(site, protocol, sim)

    @classmethod
    def from_motion(
        cls, motion: Any, assignment: dict[str, str], noise: Any = None, seed: int = 0, **kw: Any
    ) -> SimulatedSuit:
        """Synthesize the signals of ``motion`` for the assigned sites (and insoles)."""
        from inference.signals.synthesis import synthesize

        sites = [s for s in assignment if s != INSOLES]
        if INSOLES in assignment:
            sites += [s for s in ("l_foot", "r_foot") if s not in sites]
        return cls(synthesize(motion, noise=noise, rng=seed, sites=tuple(sites)), assignment, seed=seed, **kw)

    def urls(self) -> dict[str, str]:
        return {site: d.url for site, d in self.devices.items()}

    def start(self) -> SimulatedSuit:
        for d in self.devices.values():
            d.sim.start()
        return self

    def stop(self) -> None:
        for d in self.devices.values():
            d.sim.stop()

    def __enter__(self) -> SimulatedSuit:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
