"""VR headset, controllers and trackers received as VMC protocol device messages over UDP.

``vmc-in://127.0.0.1:39540?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL[&pelvis=SERIAL]`` binds
that address (a VR-to-VMC bridge on this machine sends there; ``0.0.0.0`` receives from
another PC, which is the user's choice to make) and maps each OpenVR serial number to a
body site. Messages of serials the URL does not name are counted (``unmapped``) and their
serials kept in ``serials_seen`` (serial -> hmd/con/tra): what a probe can show a user to
write into the URL.

One device serves several sites, which no other driver does. The smallest fit with the
``Device`` API: every sample is one site's pose, ``Sample.quat`` its orientation (device ->
world, our frame) and ``Sample.extra`` its ``site``, ``position`` (3,) m, ``serial`` and
``kind``; ``device_time`` is the bundle's ``/VMC/Ext/T`` (the sender's clock) when it
carries one. Beside the sample stream, ``pose(site)`` gives the latest pose of a site with
its session time of arrival, for a consumer that polls.

Each sample also carries the IMU channels its pose implies (``free_acc``, ``acc``,
``gyro``: ``implied_imu.py``, from a short fit over the site's last poses), so the hub,
the calibration and the model read a tracked site as they read an IMU at it. The hub
(``drivers/hub``) takes the device under one name, reads it once and routes its samples
by ``extra["site"]`` into one ring per site, named by ``site_names`` (``MODEL_SITES``:
the model's sensor site each tracked point stands for).
"""

from __future__ import annotations

import ipaddress
import select
import socket
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..base import Device, DeviceGone, Sample
from ..urls import build_url
from . import protocol as vmc
from .implied_imu import ImpliedImu

# the body sites a VR device can stand for: the three-point set, a waist tracker, feet trackers
TRACKED_SITES: tuple[str, ...] = ("head", "l_hand", "r_hand", "pelvis", "l_foot", "r_foot")
# the model's sensor site (inference.body.skeleton.SITES) a tracked point stands for: a controller
# held in the fist moves with the hand, whose sensor site is the wrist's (the grip's offset from
# it is a fixed mounting the calibration finds, as an IMU strap's)
MODEL_SITES: dict[str, str] = {"head": "head", "l_hand": "l_wrist", "r_hand": "r_wrist", "pelvis": "pelvis",
                               "l_foot": "l_foot", "r_foot": "r_foot"}
DEFAULT_PORT = 39540  # the VMC performer's usual receiving port (protocol.vmc.info)
_MAX_DATAGRAMS = 512  # per wake-up: a bridge sends one bundle per frame, 90 Hz at most


@dataclass(frozen=True, slots=True)
class TrackedPose:
    """A site's latest pose: ``position`` (3,) m and ``quat`` (w, x, y, z) device -> world in
    our frame, ``t`` the session time it arrived, ``sender_time`` its ``/VMC/Ext/T``."""

    site: str
    serial: str
    kind: str
    position: np.ndarray
    quat: np.ndarray
    t: float
    sender_time: float | None


class VmcInDevice(Device):
    """Receives VMC device messages on ``host:port`` for the sites in ``serials``
    (site -> OpenVR serial). ``prefer_local``: of a serial sent in both forms, use
    ``/Pos/Local`` (the spec's "device raw scale") rather than ``/Pos``; a serial sent in one
    form only is used in that form. ``latency_ms``: how much older a pose is than its bundle
    (the runtime's tracking latency, when known): the hub dates the samples that much
    earlier (``pose_age``), so they line up with IMUs that have none."""

    scheme = "vmc-in"
    kind = "tracked"

    def __init__(self, host: str, port: int, serials: dict[str, str], *, prefer_local: bool = False,
                 latency_ms: float = 0.0, **kw: Any) -> None:
        super().__init__(kw.pop("device_id", None) or "vr", **kw)
        unknown = sorted(set(serials) - set(TRACKED_SITES))
        if unknown:
            raise ValueError(f"vmc-in URL: unknown site(s) {', '.join(unknown)} (known: {', '.join(TRACKED_SITES)})")
        if not serials:
            raise ValueError("vmc-in URL names no site: add e.g. ?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL")
        by_serial: dict[str, str] = {}
        for site, serial in serials.items():
            if not serial:
                raise ValueError(f"vmc-in URL: site {site} has an empty serial")
            if serial in by_serial:
                raise ValueError(f"vmc-in URL: serial {serial!r} given for both {by_serial[serial]} and {site}")
            by_serial[serial] = site
        self.host, self.port = host, int(port)
        self.serials = dict(serials)
        self.prefer_local = prefer_local
        if not 0.0 <= latency_ms <= 500.0:
            raise ValueError(f"vmc-in URL: latency_ms={latency_ms:g} is not a tracking latency (0-500 ms)")
        self.latency_ms = float(latency_ms)
        self.pose_age = self.latency_ms / 1000.0  # s: read by the hub (drivers/hub/readers.py: Track)
        self._site_of = by_serial
        self._family = socket.AF_INET6 if ipaddress.ip_address(host).version == 6 else socket.AF_INET
        self._sock: socket.socket | None = None
        self._pending: deque[Sample] = deque()
        self._forms: dict[str, set[bool]] = {}
        self._latest: dict[str, TrackedPose] = {}
        self._latest_lock = threading.Lock()
        self._implied = {site: ImpliedImu() for site in self.serials}
        self.serials_seen: dict[str, str] = {}
        self.unmapped = 0

    @classmethod
    def from_url(cls, netloc: str, params: dict[str, str], **kw: Any) -> VmcInDevice:
        host, port = split_netloc(netloc)
        serials = {k: v for k, v in params.items() if k in TRACKED_SITES}
        other = sorted(set(params) - set(TRACKED_SITES) - {"id", "reconnect", "local", "latency_ms"})
        if other:
            raise ValueError(f"vmc-in URL: unknown parameter(s) {', '.join(other)} "
                             f"(sites: {', '.join(TRACKED_SITES)}; local=1 prefers /Pos/Local; latency_ms=MS)")
        local = params.get("local", "0").lower() in ("1", "true", "yes", "on")
        try:
            latency = float(params.get("latency_ms", "0"))
        except ValueError:
            raise ValueError(f"vmc-in URL: latency_ms={params['latency_ms']!r} is not a number") from None
        return cls(host, port, serials, prefer_local=local, latency_ms=latency, **kw)

    @property
    def sites(self) -> tuple[str, ...]:
        return tuple(self.serials)

    @property
    def site_names(self) -> dict[str, str]:
        """Each of ``sites`` -> the model's sensor site it stands for (the hub's site name)."""
        return {s: MODEL_SITES[s] for s in self.serials}

    def describe(self) -> str:
        host = f"[{self.host}]" if self._family == socket.AF_INET6 else self.host
        return build_url("vmc-in", f"{host}:{self.port}", **self.serials,
                         local=1 if self.prefer_local else None,
                         latency_ms=f"{self.latency_ms:g}" if self.latency_ms else None)

    def pose(self, site: str) -> TrackedPose | None:
        """The latest pose of ``site`` (None before the first), whichever thread reads."""
        if site not in self.serials:
            raise KeyError(f"{site!r} is not a site of {self.describe()} (sites: {', '.join(self.sites)})")
        with self._latest_lock:
            return self._latest.get(site)

    # --- transport ---------------------------------------------------------------------------------------
    def _open(self) -> None:
        s = socket.socket(self._family, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self.host, self.port))
        except OSError as exc:
            s.close()
            raise DeviceGone(f"cannot bind {self.host}:{self.port}: {exc.strerror or exc}") from exc
        if self.port == 0:
            self.port = int(s.getsockname()[1])
        self._sock = s
        self._pending.clear()
        self._forms.clear()
        for imu in self._implied.values():
            imu.reset()

    def _close(self) -> None:
        s, self._sock = self._sock, None
        if s is not None:
            s.close()

    def fileno(self) -> int | None:
        s = self._sock
        return None if s is None or not self._connected else s.fileno()

    def _receive(self, timeout: float | None) -> None:
        """Wait up to ``timeout`` for a datagram, then decode every datagram queued."""
        sock = self._sock
        if sock is None:
            raise DeviceGone("socket closed")
        r, _, _ = select.select([sock], [], [], timeout)
        if not r:
            return
        for _ in range(_MAX_DATAGRAMS):
            try:
                data = sock.recv(65536, socket.MSG_DONTWAIT)
            except BlockingIOError:
                break
            # each datagram stamped as it is taken, never before: one stamp per wake-up taken
            # before the loop dated the datagrams that came in while the loop decoded (ms each
            # when the process is busy) too early, and the hub's clock model, which trusts the
            # earliest arrivals, then put the whole rig up to 90 ms early
            now = self.clock()
            try:
                poses = vmc.decode(data)
            except ValueError:
                self.stats.bad_frame += 1
                continue
            self._accept(poses, now)

    def _accept(self, poses: list[vmc.TrackedSample], now: float) -> None:
        for p in poses:
            self.serials_seen.setdefault(p.serial, p.kind)
            if p.serial in self._site_of:
                self._forms.setdefault(p.serial, set()).add(p.local)
        for p in poses:
            site = self._site_of.get(p.serial)
            if site is None:
                self.unmapped += 1
                continue
            if p.local != self.prefer_local and self.prefer_local in self._forms[p.serial]:
                continue  # the same device in the preferred form is (or was) in the stream
            pose = TrackedPose(site, p.serial, p.kind, p.position, p.quat, now, p.sender_time)
            with self._latest_lock:
                self._latest[site] = pose
            imu = self._implied[site].update(now if p.sender_time is None else p.sender_time, p.position, p.quat)
            self._pending.append(Sample(now, p.sender_time, self.device_id, None, quat=p.quat,
                                        free_acc=None if imu is None else imu.free_acc,
                                        acc=None if imu is None else imu.acc,
                                        gyro=None if imu is None else imu.gyro,
                                        extra={"site": site, "position": p.position, "serial": p.serial,
                                               "kind": p.kind}))

    def _read(self, timeout: float | None) -> Sample | None:
        if not self._pending:
            self._receive(timeout)
        return self._pending.popleft() if self._pending else None

    def _read_many(self, timeout: float | None, max_samples: int) -> list[Sample]:
        self._receive(0.0 if self._pending else timeout)
        n = min(max_samples, len(self._pending))
        return [self._pending.popleft() for _ in range(n)]


def split_netloc(netloc: str) -> tuple[str, int]:
    """``127.0.0.1:39540`` or ``[::1]:39540`` -> (host, port); the port defaults to 39540.
    The host must be an IP address: a name would need resolving, which a receiver does not."""
    text = netloc.strip()
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port_s = rest[1:] if rest.startswith(":") else ""
    else:
        host, sep, port_s = text.rpartition(":")
        if not sep:
            host, port_s = text, ""
    if not host:
        raise ValueError(f"vmc-in URL needs host:port, e.g. vmc-in://127.0.0.1:{DEFAULT_PORT}, not {netloc!r}")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise ValueError(f"vmc-in URL: host {host!r} is not an IP address (127.0.0.1 for this machine, "
                         "0.0.0.0 to receive from another PC)") from None
    if port_s and not port_s.isdigit():
        raise ValueError(f"vmc-in URL: port {port_s!r} is not a number")
    port = int(port_s) if port_s else DEFAULT_PORT
    if not 0 <= port < 65536:
        raise ValueError(f"vmc-in URL: port {port} is out of range")
    return host, port
