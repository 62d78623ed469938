"""The body on Lab Streaming Layer: what a lab records next to EEG, EMG, eye tracking or
force plates with LabRecorder, all on one clock.

Three outlets (names start with ``prefix``, default "imucap"):

- "imucap body", type MoCap, 20 Hz, float32: per segment the orientation quaternion
  (w, x, y, z) of R_WB, the root (pelvis joint) position, the 24 joint positions and the
  4 foot contacts (1 = on the ground), in our world frame (Z up, X forward, metres);
- "imucap sensors", type MoCap, 60 Hz, float32: per sensor site (all 13, NaN where no
  sensor is worn or it dropped out) the calibrated segment orientation (w, x, y, z) and
  the world acceleration (gravity removed, m/s^2), from ``Calibration.apply``; nothing is
  sent before the first calibration;
- "imucap markers", type Markers, irregular, string: every pipeline event
  ("kind: detail") and every calibration taking effect;
- "imucap confidence", type MoCap, 20 Hz, float32, once poses carry a spread (``--confidence``):
  per segment how far the model's other inpaintings fell from the pose (degrees; 0 where a
  sensor measured it) and the root's (metres), stamped like the body sample it belongs to
  (docs/confidence.md).

The channel labels, units and types are in each stream's XML header
(``desc/channels/channel``), with the frame and quaternion order in ``desc/reference``.

Time stamps: a sample is stamped with the time its sensors measured it, not when it was
sent. Pipeline times are ``time.monotonic()`` seconds; LSL's clock is liblsl's
``local_clock()`` (a steady clock too, but not necessarily with the same zero), so the
offset between the two is measured once when the sink starts (the best of a few
back-to-back readings) and added to every time. ``clock_map`` first takes pipeline times
to ``time.monotonic()`` when they are on another clock (a replayed recording's times).

Reach: with ``local_only`` (the default: nothing beyond loopback unless the user names a
host) liblsl is configured to announce the streams only on this machine
(``ResolveScope = machine``); liblsl takes its configuration once per process, so the
first LSL sink of a process decides. Its data port still listens on every interface
(liblsl has no setting for that): use a firewall on an untrusted network.
"""

from __future__ import annotations

import ctypes
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from app.live import LivePose, Sink
from calibration import Calibration
from drivers.hub import HubFrame
from inference.body.rotations import matrix_to_quat
from inference.body.skeleton import CONTACTS, N_SITES, SEGMENTS, SITE_INDEX, SITES

POSE_RATE = 20.0
SENSOR_RATE = 60.0
_LOCAL_CONFIG = "[ports]\nIPv6 = disable\n[multicast]\nResolveScope = machine\nListenAddress = 127.0.0.1\n"
_configured: bool | None = None  # the reach liblsl was set up with in this process


def _pylsl() -> Any:
    try:
        import pylsl
    except (ImportError, OSError, RuntimeError) as e:  # pylsl raises RuntimeError without liblsl
        raise RuntimeError(f"--stream lsl needs pylsl and liblsl ({e}); pylsl's Linux x86_64 wheel carries "
                           "liblsl, elsewhere install it (conda install -c conda-forge liblsl) and set PYLSL_LIB "
                           "to the library") from e
    return pylsl


def configure_reach(pylsl: Any, local_only: bool) -> None:
    """Keep the streams' announcements on this machine (see module doc); a no-op when the
    process already chose, with a warning if it chose the other way."""
    global _configured
    if _configured is not None:
        if _configured != local_only:
            print(f"lsl: liblsl is already set up for {'this machine' if _configured else 'the network'} in "
                  "this process; the streams keep that reach", file=sys.stderr)
        return
    _configured = local_only
    if local_only:
        fn = getattr(pylsl.lib.lib, "lsl_set_config_content", None)
        if fn is None:
            print("lsl: this liblsl cannot be configured from code; the streams are visible on the network",
                  file=sys.stderr)
            return
        fn.argtypes = [ctypes.c_char_p]
        fn.restype = None
        fn(_LOCAL_CONFIG.encode())


def lsl_clock_offset(local_clock: Callable[[], float], monotonic: Callable[[], float] = time.monotonic,
                     tries: int = 9) -> float:
    """``local_clock() - monotonic()``: of a few readings bracketed by two monotonic reads,
    the one with the tightest bracket (least disturbed by a thread switch)."""
    best = (np.inf, 0.0)
    for _ in range(tries):
        a = monotonic()
        lc = local_clock()
        b = monotonic()
        best = min(best, (b - a, lc - 0.5 * (a + b)))
    return best[1]


Channel = tuple[str, str, str]  # label, unit, type


def body_channels() -> list[Channel]:
    """The body stream's layout (175 channels)."""
    out: list[Channel] = []
    for s in SEGMENTS:
        out += [(f"{s}_q{c}", "quaternion", f"Orientation{k}") for c, k in zip("wxyz", "ABCD")]
    out += [(f"root_{c}", "meters", f"Position{c.upper()}") for c in "xyz"]
    for s in SEGMENTS:
        out += [(f"{s}_{c}", "meters", f"Position{c.upper()}") for c in "xyz"]
    out += [(f"contact_{c}", "boolean", "Contact") for c in CONTACTS]
    return out


def sensor_channels() -> list[Channel]:
    """The sensor stream's layout (13 sites x 7 channels)."""
    out: list[Channel] = []
    for s in SITES:
        out += [(f"{s}_q{c}", "quaternion", f"Orientation{k}") for c, k in zip("wxyz", "ABCD")]
        out += [(f"{s}_a{c}", "m/s^2", f"Acceleration{c.upper()}") for c in "xyz"]
    return out


def confidence_channels() -> list[Channel]:
    """The confidence stream's layout (24 segments + the root)."""
    return [(f"{s}_spread", "degrees", "Spread") for s in SEGMENTS] + [("root_spread", "meters", "Spread")]


def confidence_sample(pose: LivePose) -> np.ndarray | None:
    """One confidence-stream sample, or None when the pose carries no spread."""
    p = pose.pose
    if p.spread_deg is None:
        return None
    root = np.nan if p.root_spread_m is None else float(p.root_spread_m)
    return np.r_[np.asarray(p.spread_deg, float).reshape(-1), root]


def body_sample(pose: LivePose) -> np.ndarray:
    """One body-stream sample, in ``body_channels`` order."""
    p = pose.pose
    return np.concatenate([matrix_to_quat(p.rot).reshape(-1), np.asarray(p.root, float).reshape(3),
                           np.asarray(p.joints, float).reshape(-1), np.asarray(p.contacts, float).reshape(-1)])


def _info(pylsl: Any, name: str, kind: str, channels: list[Channel], rate: float, fmt: Any, source: str,
          what: str) -> Any:
    info = pylsl.StreamInfo(name, kind, len(channels), rate, fmt, source)
    d = info.desc()
    d.append_child_value("manufacturer", "imucap")
    d.append_child_value("description", what)
    ref = d.append_child("reference")
    ref.append_child_value("frame", "world: right-handed, Z up, X = the subject's forward at calibration, "
                                    "Y = left; origin on the floor")
    ref.append_child_value("quaternion", "w,x,y,z; rotates segment frame to world (R_WB); identity = T-pose")
    ref.append_child_value("timestamps", "when the sensors measured the sample (LSL clock)")
    chans = d.append_child("channels")
    for label, unit, typ in channels:
        c = chans.append_child("channel")
        c.append_child_value("label", label)
        c.append_child_value("unit", unit)
        c.append_child_value("type", typ)
    return info


class LslSink(Sink):
    """The three outlets above; ``sensors``/``markers`` False leaves those out."""

    kind = "lsl"

    def __init__(self, prefix: str = "imucap", local_only: bool = True,
                 clock_map: Callable[[float], float] | None = None, sensors: bool = True,
                 markers: bool = True) -> None:
        pylsl = _pylsl()
        configure_reach(pylsl, local_only)
        self._clock_map = clock_map
        self.offset = lsl_clock_offset(pylsl.local_clock)
        self.names = {"body": f"{prefix} body"}
        self.counts = {"body": 0}
        self.body = pylsl.StreamOutlet(_info(
            pylsl, self.names["body"], "MoCap", body_channels(), POSE_RATE, pylsl.cf_float32, f"{prefix}-body",
            "reconstructed full body (DiffusionPoser): segment orientations, root, joints, foot contacts"))
        self.sensors = self.markers = None
        if sensors:
            self.names["sensors"], self.counts["sensors"] = f"{prefix} sensors", 0
            self.sensors = pylsl.StreamOutlet(_info(
                pylsl, self.names["sensors"], "MoCap", sensor_channels(), SENSOR_RATE, pylsl.cf_float32,
                f"{prefix}-sensors", "calibrated IMU sites: segment orientation and world acceleration"))
        if markers:
            self.names["markers"], self.counts["markers"] = f"{prefix} markers", 0
            self.markers = pylsl.StreamOutlet(_info(
                pylsl, self.names["markers"], "Markers", [("event", "", "Marker")], pylsl.IRREGULAR_RATE,
                pylsl.cf_string, f"{prefix}-markers", "session events: markers, notes, devices lost/back"))
        self.calibration: Calibration | None = None
        self._pylsl, self._prefix = pylsl, prefix
        self.confidence: Any = None  # opened with the first pose that carries a spread

    def _confidence_outlet(self) -> Any:
        if self.confidence is None:
            pylsl, prefix = self._pylsl, self._prefix
            self.names["confidence"], self.counts["confidence"] = f"{prefix} confidence", 0
            self.confidence = pylsl.StreamOutlet(_info(
                pylsl, self.names["confidence"], "MoCap", confidence_channels(), POSE_RATE, pylsl.cf_float32,
                f"{prefix}-confidence", "per segment the spread of the model's other inpaintings (0 = measured), "
                "and the root's; the time stamps of the body stream's samples"))
        return self.confidence

    def lsl_time(self, t: float) -> float:
        """A pipeline time on the LSL clock."""
        return (self._clock_map(t) if self._clock_map is not None else t) + self.offset

    def on_pose(self, pose: LivePose) -> None:
        if self.body is None:
            return
        t = self.lsl_time(pose.t)
        self.body.push_sample(body_sample(pose).tolist(), t)
        self.counts["body"] += 1
        spread = confidence_sample(pose)
        if spread is not None:
            self._confidence_outlet().push_sample(spread.tolist(), t)
            self.counts["confidence"] += 1

    def on_calibration(self, calibration: Calibration, t: float) -> None:
        self.calibration = calibration
        self.on_event(t, "calibration", "took effect")

    def on_frame(self, frame: HubFrame) -> None:
        if self.sensors is None or self.calibration is None:
            return
        R, a = self.calibration.apply(frame.quat, frame.free_acc, frame.acc, sites=frame.sites)
        ok = np.asarray(frame.present, bool) & np.all(np.isfinite(R), axis=(-1, -2))
        x = np.full((N_SITES, 7), np.nan)
        idx = np.array([SITE_INDEX[s] for s in frame.sites], dtype=int)
        if ok.any():
            x[idx[ok], :4] = matrix_to_quat(R[ok])
            x[idx[ok], 4:] = a[ok]
        self.sensors.push_sample(x.reshape(-1).tolist(), self.lsl_time(frame.t))
        self.counts["sensors"] += 1

    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        if self.markers is None:
            return
        self.markers.push_sample([f"{kind}: {detail}" if detail else kind], self.lsl_time(t))
        self.counts["markers"] += 1

    def close(self) -> None:
        # liblsl closes an outlet when it is released
        self.body = self.sensors = self.markers = self.confidence = None

    def summary(self) -> dict[str, Any]:
        return {"kind": self.kind, "streams": dict(self.names), "samples": dict(self.counts),
                "clock_offset_s": round(self.offset, 6)}
