"""A simulated VR rig: headset, two hand controllers and (optionally) a waist tracker that a
VR-to-VMC bridge would report from SteamVR, sent as VMC protocol device messages (OSC
bundles over UDP, python-osc's client) to a ``vmc-in://`` receiver on loopback.

In its own process: ``python -m sim_devices.vr_rig_process`` (``sim_devices/vr_rig_process.py``:
that module picks the motion, which a module of ``sim_devices.devices`` may not, as
``sim_devices.motions`` sits above the devices).

Where the devices sit on the body (``tracked_points``): ``inference/body/tracked.py``, one
placement for the rig, the training and the evaluation (the headset between the eyes, a
controller's grip in the fist turned ``GRIP_PITCH_DEG`` about the hand's lateral axis, the
waist tracker at the pelvis sensor site). Calibration must find the grip for a real
controller (docs/vr_input.md).

Tracking error and latency (``TrackingNoise``), consumer SteamVR / Quest class:
- position: white jitter of 1 mm per axis plus a slow wander of 2 mm per axis
  (first-order Gauss-Markov, 2 s correlation time): together about 3.9 mm RMS in 3D. Jost
  et al. 2019 (J. Biomech. 97:109379, HTC Vive controllers against a robot and an optical
  reference) found 0.6-0.7 mm for robot-driven translations and 3.97 +- 3.37 mm during human
  movement.
- orientation: white jitter of 0.3 deg per axis (about 0.5 deg RMS); the same study found
  0.46-0.66 deg mean error in rotated angle.
- latency 15 ms, the pose sent at t being the body's at t - 15 ms. Warburton et al. 2022
  (Behav. Res. Methods 55:3658, motion-to-photon of Vive, Rift, Rift S, Index controllers)
  measured 21-42 ms at the onset of a movement, falling to 2-13 ms once the runtime's
  prediction has caught up; 15 ms sits between.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pythonosc.udp_client import UDPClient

from drivers.urls import build_url
from drivers.vmc import protocol as vmc
from drivers.vmc.device import DEFAULT_PORT
from inference.body import tracked
from inference.body.conventions import quat_z, rot_z
from inference.body.motion import Motion
from inference.body.rotations import matrix_to_quat, quat_continuous, quat_exp, quat_multiply

from .base import DeviceFaults, SimDevice
from .can_loopback import is_loopback

# the devices' placement on the body is the training's and the evaluation's too
# (inference/body/tracked.py); re-exported here for the rig's users
GRIP_PITCH_DEG, EYE_HEIGHT_RATIO = tracked.GRIP_PITCH_DEG, tracked.EYE_HEIGHT_RATIO
grip_rotation = tracked.grip_rotation

ROLES: dict[str, str] = {"head": "hmd", "l_hand": "con", "r_hand": "con", "pelvis": "tra"}
DEFAULT_SERIALS: dict[str, str] = {"head": "SIM-HMD", "l_hand": "SIM-CON-L", "r_hand": "SIM-CON-R",
                                   "pelvis": "SIM-TRK-WAIST"}
DEFAULT_SITES: tuple[str, ...] = ("head", "l_hand", "r_hand")


@dataclass(frozen=True)
class TrackingNoise:
    """Tracking error and latency of a consumer headset (module docstring for the sources)."""

    jitter_m: float = 0.001  # white, per axis
    wander_m: float = 0.002  # Gauss-Markov, per axis
    wander_tau_s: float = 2.0
    jitter_deg: float = 0.3  # white, per axis
    latency_s: float = 0.015

    @property
    def position_rms_3d_m(self) -> float:
        return math.sqrt(3.0 * (self.jitter_m ** 2 + self.wander_m ** 2))


NO_NOISE = TrackingNoise(0.0, 0.0, 2.0, 0.0, 0.0)


def tracked_points(motion: Motion, sites: tuple[str, ...] = DEFAULT_SITES) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per site, the device's position (T, 3) and orientation (T, 4, w x y z) over the motion."""
    unknown = [s for s in sites if s not in ROLES]
    if unknown:
        raise ValueError(f"no VR device for site {unknown[0]!r} (known: {', '.join(ROLES)})")
    J = motion.joints()
    pos = tracked.point_positions(motion.rot, J, tracked.point_locals(motion.body.offsets, motion.body.height))
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for site in sites:
        k = tracked.TRACKED_POINTS.index(site)
        Rd = motion.rot[:, tracked.POINT_SEGMENTS[k]]
        if site in ("l_hand", "r_hand"):
            Rd = Rd @ grip_rotation()
        out[site] = (np.ascontiguousarray(pos[:, k]), quat_continuous(matrix_to_quat(Rd)))
    return out


class TrackedSource:
    """The devices' clean poses as functions of time, looping over the clip (linear for
    positions, normalised linear for quaternions between frames a few ms apart).

    ``frame_yaw_deg``, ``frame_origin``: the VR system's own frame in the motion's world
    (a turn about the vertical and a floor-level offset: where the room setup put its
    origin and its forward); the poses are sent in that frame, as a runtime sends them."""

    def __init__(self, motion: Motion, sites: tuple[str, ...] = DEFAULT_SITES, frame_yaw_deg: float = 0.0,
                 frame_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.sites = tuple(sites)
        self.fps = float(motion.fps)
        self.points = tracked_points(motion, self.sites)
        if frame_yaw_deg or any(frame_origin):
            # world -> VR frame: p_vr = Rz(-yaw) (p - origin), q_vr = q_z(-yaw) q
            yaw = math.radians(frame_yaw_deg)
            qz, Rz = quat_z(-yaw), rot_z(-yaw)
            self.points = {s: ((P - np.asarray(frame_origin)) @ Rz.T, quat_multiply(qz, Q))
                           for s, (P, Q) in self.points.items()}
        self.n = motion.n_frames
        self.duration = self.n / self.fps
        self.height = float(motion.body.height)

    def at(self, t: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        x = (t % self.duration) * self.fps
        i0 = int(x) % self.n
        i1 = min(i0 + 1, self.n - 1)
        w = x - int(x)
        out = {}
        for site, (P, Q) in self.points.items():
            q = (1 - w) * Q[i0] + w * Q[i1]
            out[site] = ((1 - w) * P[i0] + w * P[i1], q / np.linalg.norm(q))
        return out


class _Datagram:
    """Bytes where python-osc's client wants a bundle (only ``dgram`` is read): a corrupted one."""

    def __init__(self, dgram: bytes) -> None:
        self.dgram = dgram


class SimVrRig(SimDevice):
    """The rig as one device thread: every 1/rate s one bundle with ``/VMC/Ext/T`` (device
    time, s), one device message per site and ``/VMC/Ext/OK``, to ``host:port`` (loopback)."""

    protocol = "vmc-in"

    def __init__(self, source: TrackedSource, rate: float = 72.0, faults: DeviceFaults | None = None,
                 name: str = "vr", host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 serials: dict[str, str] | None = None, noise: TrackingNoise | None = None) -> None:
        super().__init__(source, rate, faults, name)
        if not is_loopback(host):
            raise ValueError(f"a simulated VR rig sends to a loopback address (127.0.0.1, ::1), not {host!r}")
        if not 60.0 <= rate <= 120.0:
            raise ValueError(f"a VR runtime reports poses at 60-120 Hz, not {rate:g}")
        self.host, self.port = host, int(port)
        self.serials = {s: (serials or {}).get(s, DEFAULT_SERIALS[s]) for s in source.sites}
        self.noise = noise or TrackingNoise()
        self._wander: dict[str, np.ndarray] | None = None
        self._last_t: float | None = None
        self._client: UDPClient | None = None

    @property
    def url(self) -> str:
        return build_url("vmc-in", f"{self.host}:{self.port}", **self.serials, id=self.name)

    def _open_transport(self) -> None:
        self._client = UDPClient(self.host, self.port)

    def _close_transport(self) -> None:
        c, self._client = self._client, None
        if c is not None:
            c.close()

    def poses(self, t: float) -> list[vmc.DevicePose]:
        """What the runtime reports at session time ``t``: the body at ``t - latency``, with
        the tracking error of each device."""
        nz = self.noise
        clean = self.source.at(max(0.0, t - nz.latency_s))
        if self._wander is None:  # the wander starts in its stationary spread
            self._wander = {s: self.rng.normal(0.0, nz.wander_m, 3) for s in clean}
        dt = 0.0 if self._last_t is None else max(0.0, t - self._last_t)
        self._last_t = t
        a = math.exp(-dt / nz.wander_tau_s) if nz.wander_tau_s > 0 else 0.0
        out = []
        for site, (p, q) in clean.items():
            w = self._wander[site]
            w[:] = a * w + math.sqrt(1.0 - a * a) * self.rng.normal(0.0, nz.wander_m, 3)
            pos = p + w + self.rng.normal(0.0, nz.jitter_m, 3)
            rot = quat_multiply(q, quat_exp(self.rng.normal(0.0, math.radians(nz.jitter_deg), 3)))
            out.append(vmc.DevicePose(ROLES[site], self.serials[site], pos, rot))
        return out

    def _make_packet(self, t: float, device_t: float, counter: int) -> Any:
        return vmc.frame_bundle(self.poses(t), sender_time=device_t)

    def _corrupt(self, packet: Any) -> Any:
        return _Datagram(super()._corrupt(packet.dgram))

    def _send(self, packet: Any) -> None:
        if self._client is None:
            raise OSError("socket closed")
        self._client.send(packet)

