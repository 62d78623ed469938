"""A simulated subject wearing a setup's devices: every device appears at the URL the
setup names (a pty linked at the serial path, a CAN channel on a bus that crosses
processes, the HID seam's socket, a UDP port), playing a subject who follows the setup's
calibration protocol and then a motion.

Each sensor has its own heading reference and mounting rotation (the noise model's
``typical``: headings uniform in +-180 deg, straps 15 deg off), so the capture's
calibration has to find them, as with real sensors. The motion played is written to a
truth file, on the same monotonic clock the capture records with, so a recording can be
scored against it (``imucap replay REC --truth TRUTH``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.capture.setup_file import Setup
from app.capture.twins import simulation_problem
from calibration.protocol import Protocol, WalkProtocol, synthesize_session, synthesize_walk_session
from drivers.urls import parse_url
from inference.body.motion import Motion
from inference.signals.site_signals import SiteSignals
from inference.signals.synthesis import NoiseModel
from sim_devices.devices import DeviceFaults, SimDevice, make_sim_device

INSOLES = "insoles"
TRUTH_FORMAT = "imucap-truth"
# A simulated VR rig reports in its own frame, as a runtime does: its origin where the room
# setup put it (on the floor, away from where the subject stands) and its forward turned from
# the subject's; the capture's calibration has to find that turn as it finds an IMU's heading.
VR_FRAME_YAW_DEG = 35.0
VR_FRAME_ORIGIN = (1.2, -0.8, 0.0)
# A person told to stand still after the walk stands until the next prompt; the simulated one
# cannot hear it and plays a fixed timeline. These seconds more of standing than the protocol's
# own 3.5 s keep the guided stand step inside the stand when the capture runs a second or two
# behind the subject (a busy machine): with 1 s to spare, a window demo's stand step once began
# after the subject had walked off (docs/testing.md).
STAND_MARGIN_S = 1.5


@dataclass
class Unplug:
    """Pull ``device``'s plug ``at`` s after the activity starts, for ``seconds``."""

    device: str
    at: float
    seconds: float

    @classmethod
    def parse(cls, text: str) -> Unplug:
        try:
            name, at, dur = text.split(":")
            return cls(name, float(at), float(dur))
        except ValueError:
            raise ValueError(f"--unplug {text!r}: expected DEVICE:AT:SECONDS, e.g. l_wrist:5:5") from None


@dataclass
class SimulatedSubject:
    setup: Setup
    activity: Motion
    lead_in: float = 8.0  # extra seconds of N-pose (or table) before the protocol: the capture starts later
    seed: int = 0
    noise: NoiseModel = field(default_factory=NoiseModel.typical)
    signals: SiteSignals | None = None
    truth: Motion | None = None

    def synthesize(self) -> tuple[SiteSignals, Motion]:
        from sim_devices.motions import generate

        sites = tuple(self.setup.sites())
        if self.setup.insoles is not None:
            sites += tuple(s for s in ("l_foot", "r_foot") if s not in sites)
        act = self.activity.resample(60.0)
        if self.setup.calibration == "walk":
            walk = generate("walk", seconds=6.0, seed=self.seed + 7, height=act.body.height)
            walk = Motion(rot=walk.rot, root=walk.root, fps=walk.fps, body=act.body, name="walk")
            base = WalkProtocol()
            proto = WalkProtocol(npose=base.npose + self.lead_in, stand=base.stand + STAND_MARGIN_S)
            sig, truth = synthesize_walk_session(act, walk, proto, noise=self.noise, rng=self.seed, sites=sites)
        else:
            proto = Protocol(table=7.0 + self.lead_in, strap=2.0, tpose=6.0, blend=1.0)
            sig, truth = synthesize_session(act, proto, noise=self.noise, rng=self.seed, sites=sites)
        self.signals, self.truth = sig, truth
        return sig, truth


def sim_device_for(url: str, name: str, signals: SiteSignals, faults: DeviceFaults, motion: Motion | None = None,
                   tracking: bool = True) -> SimDevice:
    """The simulated device that answers at ``url`` (its scheme decides the protocol);
    ``ValueError`` naming the URL when no simulator can serve it (``twins.simulation_problem``).
    A VR rig (``vmc-in``) plays ``motion``'s tracked points (with consumer tracking error and
    latency when ``tracking``), the same motion and clock as the IMUs' signals."""
    problem = simulation_problem(url)
    if problem is not None:
        raise ValueError(f"{name} = {url}: {problem}")
    u = parse_url(url)
    if u.scheme == "vmc-in":
        return sim_rig_for(url, name, motion, faults, tracking)
    kw: dict[str, Any] = {}
    if u.scheme in ("xbus", "bno08x-rvc"):
        Path(u.path).parent.mkdir(parents=True, exist_ok=True)  # e.g. /tmp/imucap-sim of the example setup
        kw["link_path"] = u.path
    elif u.scheme == "xsens-can":
        kw.update(interface=u.netloc, channel=u.path.lstrip("/"), id_offset=u.get_int("id_offset", 0))
    elif u.scheme == "dualsense":
        Path(u.path).parent.mkdir(parents=True, exist_ok=True)
        kw["socket_path"] = u.path
    elif u.scheme == "moticon-udp":
        host, _, port = u.netloc.rpartition(":")
        kw.update(host=host or "127.0.0.1", port=int(port))
    elif u.scheme == "movella-dot":
        Path(str(u.get("ble"))).mkdir(parents=True, exist_ok=True)
        kw.update(folder=u.get("ble"), address=u.netloc, rate=u.get_float("rate", 60.0))
    elif u.scheme == "ximu3":
        port = int(u.path.lstrip("/"))
        kw.update(host=u.get("ip", "127.0.0.1"), port=port, send_port=u.get_int("send_port", port + 1000),
                  rate=u.get_float("rate", 100.0))
    else:
        raise ValueError(f"{url}: no simulated twin for {u.scheme!r}")
    if u.scheme == "moticon-udp":
        return make_sim_device(u.scheme, signals, INSOLES, faults=faults, name=INSOLES, **kw)
    return make_sim_device(u.scheme, signals, name, faults=faults, name=name, **kw)


def sim_rig_for(url: str, name: str, motion: Motion | None, faults: DeviceFaults, tracking: bool) -> SimDevice:
    """The simulated VR rig sending to a ``vmc-in`` URL's port: its sites and serials, the
    rig's frame turned and moved from the motion's (``VR_FRAME_YAW_DEG``)."""
    import drivers
    from sim_devices.devices.vr_rig import NO_NOISE, SimVrRig, TrackedSource, TrackingNoise

    if motion is None:
        raise ValueError(f"{name} = {url}: a simulated VR rig plays a motion, and none was given")
    dev = drivers.make_device(url)  # its sites and serials; nothing is bound
    source = TrackedSource(motion, dev.sites, VR_FRAME_YAW_DEG, VR_FRAME_ORIGIN)  # type: ignore[attr-defined]
    return SimVrRig(source, 72.0, faults, name=name, host=dev.host, port=dev.port,  # type: ignore[attr-defined]
                    serials=dev.serials, noise=TrackingNoise() if tracking else NO_NOISE)  # type: ignore[attr-defined]


def rig_sensor_to_bone(motion: Motion, url: str) -> np.ndarray:
    """(P, 3, 3) each rig device's frame in its site's segment at the motion's first frame
    (a controller in the fist turns with the hand, so against the forearm it holds only
    while the wrist does)."""
    import drivers
    from inference.body.rotations import quat_to_matrix
    from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
    from sim_devices.devices.vr_rig import tracked_points

    dev = drivers.make_device(url)
    points = tracked_points(motion, dev.sites)  # type: ignore[attr-defined]
    out = []
    for site, model_site in dev.site_names.items():  # type: ignore[attr-defined]
        R_WS = quat_to_matrix(points[site][1][0])
        out.append(R_WS.T @ motion.rot[0, SITE_SEGMENT_INDEX[SITE_INDEX[model_site]]])
    return np.stack(out)


class SimulatedSetup:
    """The running simulation: devices started, truth known."""

    def __init__(self, subject: SimulatedSubject, unplug: list[Unplug] | None = None) -> None:
        sig, truth = subject.synthesize() if subject.signals is None else (subject.signals, subject.truth)
        self.subject, self.signals, self.truth = subject, sig, truth
        act0 = float(sig.meta["activity_start"])
        self.devices: dict[str, SimDevice] = {}
        for k, (name, url) in enumerate(subject.setup.urls().items()):
            cuts = [(u.at + act0, u.seconds) for u in unplug or [] if u.device == name]
            f = DeviceFaults(clock_offset=50.0 * (k + 1), drift_ppm=(-1) ** k * 15.0 * (k + 1), disconnects=cuts,
                             seed=subject.seed + k)
            self.devices[name] = sim_device_for(url, name, sig, f, truth, tracking=subject.noise != NoiseModel())
        missing = [u.device for u in unplug or [] if u.device not in self.devices]
        if missing:
            raise ValueError(f"--unplug: no device {missing[0]!r} in the setup ({', '.join(self.devices)})")
        self.t0: float | None = None

    def start(self) -> SimulatedSetup:
        started: list[SimDevice] = []
        try:
            for d in self.devices.values():
                d.start()
                started.append(d)
        except BaseException:
            for d in started:  # a port already taken: leave nothing half up
                d.stop()
            raise
        self.t0 = float(np.mean([d.started_at for d in self.devices.values()]))
        return self

    def stop(self) -> None:
        # every loop told first: on a starved machine each join may take its whole 2 s, and seven in
        # turn outlasted a harness's 10 s terminate, which killed the simulator before it wrote its
        # send log (the wireless capture test's "again" run)
        for d in self.devices.values():
            d.request_stop()
        for d in self.devices.values():
            d.stop()

    @property
    def duration(self) -> float:
        return len(self.signals) / self.signals.fps

    def stats(self) -> dict[str, dict[str, int]]:
        return {n: dict(d.stats) for n, d in self.devices.items()}

    def write_truth(self, path: str | Path) -> Path:
        """The motion played, with the monotonic time of its first frame and the activity's
        start: what ``imucap replay --truth`` scores a recording against."""
        tr = self.truth
        sites = self.subject.setup.sites()
        R_SB = self.signals.meta["R_SB"][[list(self.signals.sites).index(s) for s in sites]]
        for entry in self.subject.setup.tracked.values():  # a rig's devices sit as tracked_points puts them
            R_SB[[sites.index(s) for s in entry.sites]] = rig_sensor_to_bone(tr, entry.url)
        return save_truth(path, tr.rot, tr.root, tr.fps, self.t0 if self.t0 is not None else 0.0,
                          float(self.signals.meta["activity_start"]), tr.body.height, tr.body.offsets,
                          sites, self.subject.setup.calibration, R_SB=R_SB)

    def write_send_logs(self, path: str | Path) -> Path:
        """Per device, the wire counter and the monotonic time of every packet sent since
        ``log_sends`` (``<name>/counter``, ``<name>/t``): a latency measurement in another
        process matches its poses back to them (the monotonic clock is the machine's)."""
        path = Path(path)
        arrays: dict[str, np.ndarray] = {}
        for name, d in self.devices.items():
            log = d.send_log or []
            arrays[f"{name}/counter"] = np.array([c for c, _ in log], np.int64)
            arrays[f"{name}/t"] = np.array([t for _, t in log], np.float64)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(path)
        return path

    def run(self, seconds: float | None = None, stop: threading.Event | None = None) -> None:
        """For ``seconds`` (None: the simulation's length, or with ``stop`` until it is set;
        the devices loop their signals meanwhile)."""
        if stop is not None and seconds is None:
            stop.wait()
            return
        end = time.monotonic() + (self.duration if seconds is None else seconds)
        while time.monotonic() < end and not (stop is not None and stop.is_set()):
            time.sleep(0.1)


def save_truth(path: str | Path, rot: np.ndarray, root: np.ndarray, fps: float, t0: float, activity_start: float,
               height: float, offsets: np.ndarray, sites: Sequence[str], protocol: str,
               R_SB: np.ndarray | None = None) -> Path:
    """Write a truth file (``read_truth``), atomically: segment orientations (T, 24, 3, 3) in
    the recording's world, the root, the session time of frame 0 (``t0``) and the time after
    it from which the motion counts (``activity_start``: the calibration before it does not).
    ``R_SB``: each site's sensor-to-bone rotation as the simulator strapped it (S, 3, 3), for
    checking what a calibration recovered."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp.npz")
    extra = {} if R_SB is None else {"R_SB": np.asarray(R_SB, np.float64)}
    np.savez_compressed(tmp, format=TRUTH_FORMAT, rot=np.asarray(rot, np.float32), root=np.asarray(root, np.float32),
                        fps=float(fps), t0=float(t0), activity_start=float(activity_start), height=float(height),
                        offsets=np.asarray(offsets), sites=np.array(list(sites)), protocol=protocol, **extra)
    tmp.replace(path)
    return path


@dataclass
class Truth:
    rot: np.ndarray
    root: np.ndarray
    fps: float
    t0: float
    activity_start: float
    height: float
    offsets: np.ndarray
    sites: tuple[str, ...] = ()
    R_SB: np.ndarray | None = None  # (S, 3, 3) per site of ``sites``, when the simulator wrote it

    def frame_at(self, t: np.ndarray) -> np.ndarray:
        """Index of the truth frame at monotonic session time(s) ``t`` (clipped)."""
        return np.clip(np.rint((np.asarray(t) - self.t0) * self.fps).astype(int), 0, len(self.rot) - 1)


def read_truth(path: str | Path) -> Truth:
    with open(path, "rb") as fh:
        if fh.read(4) != b"PK\x03\x04":  # an .npz is a zip; np.load would speak of pickles
            raise ValueError(f"{path}: not an imucap truth file (.npz); to score against another system's file "
                             f"(BVH, MVNX, C3D, TRC, .mot) use: imucap validate REC.h5 --reference {path}")
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a truth file ({exc})") from None
    with z:
        if "format" not in z or str(z["format"]) != TRUTH_FORMAT:
            raise ValueError(f"{path}: not an imucap truth file (written by 'imucap devices simulate --truth')")
        return Truth(z["rot"].astype(np.float64), z["root"].astype(np.float64), float(z["fps"]), float(z["t0"]),
                     float(z["activity_start"]), float(z["height"]), z["offsets"].astype(np.float64),
                     tuple(str(s) for s in z["sites"]) if "sites" in z else (),
                     z["R_SB"].astype(np.float64) if "R_SB" in z else None)
