"""Xsens MVN's MVNX export (the XML file MVN Analyze / Animate writes for a take): the
suit's sensors, read into one ``DeviceLog`` each, so ``imucap import`` can re-run an MVN
session with a few of its sensors.

What the file holds (MVNX version 4, namespace ``http://www.xsens.com/mvn/mvnx``, as in
MVN's schema and the public sample takes the format was checked against): ``subject``
with its ``frameRate``, ``segments``, ``sensors`` (one ``<sensor label="..."/>`` per
sensor, labelled by the segment it is strapped to: ``Pelvis``, ``T8``, ``Head``,
``RightShoulder``, ``RightUpperArm``, ``RightForeArm``, ``RightHand``, ``RightUpperLeg``,
``RightLowerLeg``, ``RightFoot`` and the left ones), then ``frames``: a few calibration
frames (``type="identity"``, ``"tpose"``, ``"tpose-isb"``) and one ``type="normal"`` frame
per sample with ``index`` and ``time`` (ms from the take's start). Each frame lists per sensor, in the
order of ``sensors``, ``sensorOrientation`` (w, x, y, z: sensor to MVN's global frame, Z
up) and ``sensorFreeAcceleration`` (m/s^2, global frame, gravity removed). There is no
sensor angular rate (``angularVelocity`` is per segment, after MVN's own fusion), so the
logs carry none and the import takes the rate from orientation.

A take cut short (MVN closed mid-export, a copy that stopped) ends without closing its
XML: the frames before the cut are kept and the cut is counted (``skipped["truncated"]``).
A frame whose sensor lists are short or not numbers is skipped and counted (``malformed``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from drivers._math import quat_conjugate, quat_rotate
from drivers.device_log import DeviceLog
from drivers.xsens_export.frames import normalise
from drivers.xsens_export.samples import G

# MVN's sensor labels (the segment each is strapped to) -> imucap's sites. The hands and
# shoulders have no site: the wrist site is the forearm's sensor, as on every other suit.
MVN_SITES: dict[str, str] = {
    "Pelvis": "pelvis", "T8": "torso", "Head": "head",
    **{f"{side}{seg}": f"{s}_{site}" for side, s in (("Left", "l"), ("Right", "r")) for seg, site in (
        ("UpperArm", "upperarm"), ("ForeArm", "wrist"), ("UpperLeg", "thigh"), ("LowerLeg", "shank"),
        ("Foot", "foot"))},
}
TITLE = "Xsens MVN export (MVNX)"


class MvnxError(ValueError):
    """An MVNX file that cannot be read; one line naming the file."""

    def __init__(self, path: str | os.PathLike, problem: str) -> None:
        super().__init__(f"{os.fspath(path)}: {problem}")


@dataclass
class MvnxTake:
    """One take's sensors: a DeviceLog per sensor (in the file's order), and what the
    file says about the take."""

    logs: list[DeviceLog]
    frame_rate: float
    info: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)

    def log(self, label: str) -> DeviceLog:
        return next(d for d in self.logs if d.name == label)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _numbers(elem: ET.Element | None, n: int) -> np.ndarray | None:
    if elem is None or not elem.text:
        return None
    try:
        v = np.array(elem.text.split(), dtype=float)
    except ValueError:
        return None
    return v if v.size == n and np.all(np.isfinite(v)) else None


def is_mvnx(path: str | os.PathLike) -> bool:
    """Whether a file starts as an MVNX file does (its root element is ``mvnx``); never raises."""
    try:
        for _event, elem in ET.iterparse(path, events=("start",)):
            return _local(elem.tag) == "mvnx"
    except (ET.ParseError, LookupError, ValueError, OSError):  # LookupError: an encoding Python lacks
        return False
    return False


def read_mvnx(path: str | os.PathLike) -> MvnxTake:
    """Every sensor of an MVNX take as a DeviceLog: times from the normal frames
    (``_frame_time``, s from the take's start), orientation as stored, specific force in the sensor's frame
    (the free acceleration with gravity put back, turned by the sensor's orientation), no
    gyro. Streams the file (a take of minutes is hundreds of MB of XML)."""
    labels: list[str] = []
    info: dict[str, str] = {"layout": "mvnx", "acc_from": "sensorFreeAcceleration", "gyro_from": "none"}
    rate = float("nan")
    t: list[float] = []
    quat: list[np.ndarray] = []
    free: list[np.ndarray] = []
    skipped = {"malformed": 0, "duplicate": 0, "truncated": 0}
    frames_elem: ET.Element | None = None
    open_elems: list[ET.Element] = []  # the elements whose end tag is still to come (a frame's parent is last)
    seen_root = False
    try:
        for event, elem in ET.iterparse(path, events=("start", "end")):
            tag = _local(elem.tag)
            if event == "start":
                open_elems.append(elem)
                if not seen_root:
                    if tag != "mvnx":
                        raise MvnxError(path, f"not an MVNX file (its root element is <{tag}>, not <mvnx>)")
                    seen_root = True
                    info["mvnx_version"] = elem.get("version", "")
                elif tag == "subject":
                    try:
                        rate = float(elem.get("frameRate", "nan"))
                    except ValueError:
                        rate = float("nan")
                    info.update(subject=elem.get("label", ""), configuration=elem.get("configuration", ""),
                                recorded=elem.get("recDate", ""))
                elif tag == "frames":
                    frames_elem = elem
                continue
            open_elems.pop()
            if tag == "mvn":
                info["mvn_version"] = elem.get("version", "")
            elif tag == "sensor" and frames_elem is None and not t:  # the list is fixed by the first frame
                labels.append(elem.get("label") or f"sensor{len(labels) + 1}")
            elif tag == "segments":
                elem.clear()  # body points: not needed, and the file's second-largest part
            elif tag == "frame":
                if elem.get("type", "normal") == "normal":
                    _take_frame(elem, len(labels), rate, t, quat, free, skipped)
                if open_elems:
                    open_elems[-1].remove(elem)  # stream: keep no frame once read
    except MvnxError:
        raise
    except (LookupError, ValueError) as exc:  # an encoding Python lacks, or one expat cannot read
        raise MvnxError(path, f"not a readable MVNX file ({exc})") from None
    except ET.ParseError as exc:
        if not seen_root:
            raise MvnxError(path, f"not an MVNX file (not XML: {exc})") from None
        if len(t) < 2:
            raise MvnxError(path, f"damaged MVNX file, no frames before the damage ({exc})") from None
        skipped["truncated"] = 1
        info["truncated"] = f"the file ends early ({exc}); the {len(t)} frames before it are kept"
    if not seen_root:
        raise MvnxError(path, "an empty file, not an MVNX take")
    return _take(path, labels, rate, t, quat, free, skipped, info)


def _frame_time(elem: ET.Element, rate: float) -> float:
    """Seconds from the take's start: the frame's index over the frame rate where the file
    has both (exact; ``time`` is whole ms, so 60 Hz frames read 16 or 17 ms apart), else
    ``time``."""
    try:
        if rate > 0 and elem.get("index") is not None:
            return float(elem.get("index", "")) / rate
    except ValueError:
        pass
    try:
        return float(elem.get("time", "")) / 1000.0
    except ValueError:
        return float("nan")


def _take_frame(elem: ET.Element, n: int, rate: float, t: list[float], quat: list[np.ndarray],
                free: list[np.ndarray], skipped: dict[str, int]) -> None:
    children = {_local(c.tag): c for c in elem}
    q = _numbers(children.get("sensorOrientation"), 4 * n)
    a = _numbers(children.get("sensorFreeAcceleration"), 3 * n)
    tt = _frame_time(elem, rate)
    if n == 0 or q is None or a is None or not np.isfinite(tt):
        skipped["malformed"] += 1
        return
    if t and tt <= t[-1]:
        skipped["duplicate"] += 1
        return
    t.append(tt)
    quat.append(q.reshape(n, 4))
    free.append(a.reshape(n, 3))


def _take(path: str | os.PathLike, labels: list[str], rate: float, t: list[float], quat: list[np.ndarray],
          free: list[np.ndarray], skipped: dict[str, int], info: dict[str, str]) -> MvnxTake:
    if not labels:
        raise MvnxError(path, "no <sensors> in the take: an MVNX export without its sensor list")
    if not t:
        why = f", and {skipped['malformed']} frames without them" if skipped["malformed"] else ""
        raise MvnxError(path, "no sensor data in the frames (export with 'Sensor orientation' and 'Sensor free "
                              f"acceleration' ticked in MVN's export settings){why}")
    tt = np.asarray(t)
    Q = np.stack(quat)  # (N, S, 4)
    F = np.stack(free)  # (N, S, 3)
    logs = []
    for k, label in enumerate(labels):
        q, ok = normalise(Q[:, k])
        acc = quat_rotate(quat_conjugate(q[ok]), F[ok, k] + np.array([0.0, 0.0, G]))
        counts = {**skipped, "no_orientation": int((~ok).sum())}
        logs.append(DeviceLog(label, label, tt[ok], q[ok], acc, np.full((len(acc), 3), np.nan),
                              skipped={key: v for key, v in counts.items() if v},
                              info={**info, "site": MVN_SITES.get(label, "")}))
    return MvnxTake(logs, rate, info, {key: v for key, v in skipped.items() if v})


__all__ = ["MVN_SITES", "TITLE", "MvnxError", "MvnxTake", "is_mvnx", "read_mvnx"]
