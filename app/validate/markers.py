"""Marker files as joint centres and segment frames: C3D (read with the pure-Python
``c3d`` package; ``read_c3d`` says why not ezc3d) and OpenSim's TRC (text).

A lab's file names its points as its software does. We take a point as one of our joint
centres (``kinematics.JOINT_NAMES``) when its label, lower-cased without a subject
prefix (``Subject:``), is our name or one of the aliases below: the joint-centre names
of Vicon's Plug-in Gait and of most lab pipelines (``LKJC``, ``RHJC``, ...), OpenSim's
(``r_knee_study``...: not centres, but on the joint's axis) and, where a lab exported
only surface markers, the lateral markers at the joint (``LKNE``, ``LANK``, ``LSHO``,
``LELB``, ``LWRA``): a joint centre a few centimetres off, which the report's mapping
lines say. Units come from the file (C3D ``POINT:UNITS``, TRC ``Units``); the up axis
is the one the legs hang along (hip above ankle), turned onto our Z (Y up is taken as
OpenSim's ground, X forward; any other heading is found by the alignment).

Surface markers beyond joint centres (``landmarks.py``): Plug-in Gait's segment axes,
anatomical landmarks (ASIS/PSIS, epicondyles, malleoli, heel, toe) giving the hip, knee
and ankle centres and the segment frames, and a static trial's landmarks carried into
the walking trial by marker clusters. A joint centre the file names (``LKJC``, ours)
wins over one computed from landmarks, which wins over a lateral marker standing in.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.export.opensim import M_OS
from app.validate.kinematics import JOINT_INDEX
from inference.body.motion import MotionFormatError
from inference.loaders.retarget import world_map

UNITS = {"m": 1.0, "mm": 0.001, "cm": 0.01, "in": 0.0254, "inch": 0.0254}

_ALIASES: dict[str, tuple[str, ...]] = {
    "hip": ("hjc", "_hip", "hipjc", "_hjc"), "knee": ("kjc", "_kjc", "kne", "knee_study", "_knee_study"),
    "ankle": ("ajc", "_ajc", "ank", "ankle_study", "_ankle_study"), "mtp": ("toe", "_toe", "mt2", "_mtp"),
    "shoulder": ("sjc", "_sjc", "sho"), "elbow": ("ejc", "_ejc", "elb"), "wrist": ("wjc", "_wjc", "wra"),
}


def _candidates(joint: str) -> list[str]:
    """Lower-case labels a file may give our joint ``joint`` (ours first)."""
    out = [joint]
    if joint[:2] in ("l_", "r_"):
        side, part = joint[0], joint[2:]
        for a in _ALIASES.get(part, ()):
            out += [f"{side}{a}", f"{side}_{a.lstrip('_')}", f"{'left' if side == 'l' else 'right'}{a.lstrip('_')}"]
    return out


@dataclass
class Markers:
    """Points of a marker file: time (T,) s, positions (T, N, 3) in the file's axes and
    metres (NaN where a point is missing), their labels, and the frame rate."""

    path: str
    t: np.ndarray
    pos: np.ndarray
    labels: list[str]
    rate: float


def map_joints(labels: list[str]) -> dict[str, int]:
    """our joint name -> index into ``labels`` (module docstring)."""
    plain = {}
    for i, lab in enumerate(labels):
        key = lab.split(":")[-1].strip().lower()
        plain.setdefault(key, i)
    out = {}
    for joint in JOINT_INDEX:
        for cand in _candidates(joint):
            if cand in plain:
                out[joint] = plain[cand]
                break
    return out


# beyond this a C3D header is not a capture (an hour at 1 kHz has 3.6 million frames)
MAX_C3D_VALUES = 50_000_000


def read_c3d(path: str | os.PathLike) -> Markers:
    """A C3D's points, read with the pure-Python ``c3d`` package: a lab's file is
    untrusted input, and ezc3d (which writes our exports) ends the process with a
    segmentation fault on some malformed files (benchmarks/fuzz.py reference-c3d found
    one), where ``c3d`` raises an exception we turn into one line naming the file."""
    from drivers.extras import need

    c3d = need("c3d", "reading a .c3d reference")

    spath = os.fspath(path)

    def bad(what: str) -> MotionFormatError:
        return MotionFormatError(spath, what)

    try:
        with open(spath, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found in file": markers only is what we want
            r = c3d.Reader(fh)
            labels = [str(s).strip() for s in r.point_labels]
            rate = float(r.point_rate)
            n_frames = int(r.last_frame) - int(r.first_frame) + 1
            if not (math.isfinite(rate) and rate > 0):
                raise bad(f"POINT:RATE is {rate}, not a frame rate")
            if not labels or int(r.point_used) != len(labels):
                raise bad(f"{int(r.point_used)} points for {len(labels)} labels")
            if n_frames < 2 or n_frames * len(labels) * 3 > MAX_C3D_VALUES:
                raise bad(f"{n_frames} frames of {len(labels)} points: not a capture")
            try:
                units = r.get("POINT:UNITS").string_value.strip().lower() or "mm"
            except (AttributeError, KeyError):
                units = "mm"
            if units not in UNITS:
                raise bad(f"POINT:UNITS {units!r} is not a length unit ({', '.join(UNITS)})")
            frames = []
            for _, pts, _ in r.read_frames(copy=True, check_nan=True):
                p = np.asarray(pts[:, :3], dtype=np.float64)
                p[pts[:, 3] < 0] = np.nan  # a negative residual: the point was not seen in that frame
                frames.append(p)
                if len(frames) > n_frames:
                    break
            first = int(r.first_frame)
    except MotionFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 -- whatever a malformed file makes the parser raise
        raise bad(f"not a readable C3D file ({type(exc).__name__}: {str(exc)[:100]})") from None
    if len(frames) < 2:
        raise bad(f"{len(frames)} readable frame(s); at least 2 are needed (file cut short?)")
    pos = np.stack(frames) * UNITS[units]
    t = (first - 1 + np.arange(len(frames))) / rate
    return Markers(spath, t, pos, labels, rate)


def read_trc(path: str | os.PathLike) -> Markers:
    """OpenSim's TRC: ``PathFileType`` line, a line of header keys and one of their values
    (``DataRate``, ``NumFrames``, ``NumMarkers``, ``Units``, ...), the marker names (each
    over three columns after ``Frame#`` and ``Time``), X/Y/Z labels, then rows."""
    spath = os.fspath(path)
    try:
        lines = Path(path).read_text(errors="strict").splitlines()
    except UnicodeDecodeError:
        raise MotionFormatError(spath, "not a text file (a TRC is tab-separated text)") from None
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise MotionFormatError(spath, "not a TRC file: the first line is not 'PathFileType ...'", 1)
    keys, vals = lines[1].split("\t"), lines[2].split("\t")
    head = {k.strip(): v.strip() for k, v in zip(keys, vals)}
    try:
        rate = float(head.get("DataRate") or head["CameraRate"])
        n_markers = int(head["NumMarkers"])
    except (KeyError, ValueError) as exc:
        raise MotionFormatError(spath, f"header line 3: no usable {exc} (DataRate, NumMarkers)", 3) from None
    units = head.get("Units", "mm").lower()
    if units not in UNITS:
        raise MotionFormatError(spath, f"Units {units!r} is not a length unit ({', '.join(UNITS)})", 3)
    if not (math.isfinite(rate) and rate > 0) or not 0 < n_markers < 100_000:
        raise MotionFormatError(spath, f"DataRate {rate} / NumMarkers {n_markers} out of range", 3)
    names = [n.strip() for n in lines[3].split("\t")[2:] if n.strip()]
    if len(names) != n_markers:
        raise MotionFormatError(spath, f"{len(names)} marker names for NumMarkers {n_markers}", 4)
    rows = []
    for no, ln in enumerate(lines[5:], start=6):
        if not ln.strip():
            continue
        cells = ln.split("\t")
        try:
            vals_ = [float(c) if c.strip() else math.nan for c in cells[1:2 + 3 * n_markers]]
        except ValueError as exc:
            raise MotionFormatError(spath, f"not a number ({exc})", no) from None
        if len(vals_) < 1 + 3 * n_markers:
            vals_ += [math.nan] * (1 + 3 * n_markers - len(vals_))
        rows.append(vals_)
        if not math.isfinite(vals_[0]):
            raise MotionFormatError(spath, "a row without a time", no)
    if len(rows) < 2:
        raise MotionFormatError(spath, f"{len(rows)} data row(s); at least 2 are needed")
    a = np.array(rows)
    return Markers(spath, a[:, 0], a[:, 1:].reshape(len(a), n_markers, 3) * UNITS[units], names, rate)


LATERAL_ONLY = {"kne", "ank", "sho", "elb", "wra", "toe"}


def marker_joints(m: Markers) -> tuple[np.ndarray, set[str], list[str]]:
    """(joints (T, 24, 3) in our Z-up world, NaN where unknown; the joints found; mapping
    lines 'ours <- theirs') of a marker file (``marker_reference`` without the frames)."""
    J, have, lines, _, _ = marker_reference(m)
    return J, have, lines


def marker_reference(m: Markers) -> tuple[np.ndarray, set[str], list[str], dict[str, np.ndarray], list[str]]:
    """(joints (T, 24, 3) in our Z-up world, NaN where unknown; the joints found; mapping
    lines 'ours <- theirs'; segment -> (T, 3, 3) frames from the markers; notes) of a marker
    file. The up axis: along which the hips stand above the ankles (or knees), on average."""
    from app.validate.landmarks import anatomy, frames_in_world, normalise, pig_frames

    found = map_joints(m.labels)
    anat = anatomy(m.pos, m.labels, 1.0)
    T = m.pos.shape[0]
    J = np.full((T, len(JOINT_INDEX), 3), np.nan)
    lines = []
    for joint, k in found.items():
        J[:, JOINT_INDEX[joint]] = m.pos[:, k]
    for joint, c in anat.centres.items():
        label = normalise(m.labels[found[joint]]) if joint in found else None
        if label is None or label[1:] in LATERAL_ONLY or label[:-1] in LATERAL_ONLY:
            J[:, JOINT_INDEX[joint]] = c
            found.pop(joint, None)
            lines.append(f"{joint} <- landmarks")
    have = set(found) | {j for j in anat.centres if f"{j} <- landmarks" in lines}
    if not have:
        raise MotionFormatError(m.path, f"none of its {len(m.labels)} points is a joint centre we know "
                                        f"(e.g. l_knee, LKJC, LKNE) or a landmark set that gives them (ASIS and "
                                        f"PSIS, epicondyles, malleoli); labels: {', '.join(m.labels[:12])}")
    up = None
    for top, bottom in (("hip", "ankle"), ("hip", "knee"), ("shoulder", "elbow")):
        d = [J[:, JOINT_INDEX[f"{s}_{top}"]] - J[:, JOINT_INDEX[f"{s}_{bottom}"]] for s in "lr"
             if f"{s}_{top}" in have and f"{s}_{bottom}" in have]
        d = np.concatenate(d) if d else np.zeros((0, 3))
        d = d[np.all(np.isfinite(d), axis=-1)]
        if len(d):
            up = d.mean(axis=0)
            break
    if up is None or not np.all(np.isfinite(up)) or np.linalg.norm(up) < 1e-6:
        raise MotionFormatError(m.path, "cannot tell which way is up: it needs hip and knee or ankle centres "
                                        f"(found {', '.join(sorted(have))})")
    k = int(np.argmax(np.abs(up)))
    # Y up is OpenSim's ground (X forward, Z right): its own map keeps X forward; else any proper turn
    W = M_OS.T if (k == 1 and up[1] > 0) else world_map(up)
    J = J @ W.T
    axes = {**anat.axes, **pig_frames(m.pos, m.labels)}  # a lab's own segment axes win
    frames = frames_in_world(axes, W)
    lines = [f"{j} <- {m.labels[k]}" for j, k in found.items()] + lines
    if frames:
        lines.append("segment frames <- " + ", ".join(
            f"{s} ({'Plug-in Gait axes' if s in pig_frames(m.pos[:1], m.labels) else 'landmarks'})"
            for s in sorted(frames)))
    return J, have, lines, frames, anat.notes


__all__ = ["Markers", "UNITS", "map_joints", "read_c3d", "read_trc", "marker_joints", "marker_reference"]
