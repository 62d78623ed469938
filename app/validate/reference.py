"""Another system's answer for a trial, whatever file it came in, as what the comparison
needs: times on the reference's own clock, joint centres in a Z-up world (metres) and,
where the file has them, global segment orientations on our 24-segment body.

Readers by extension: ``.bvh``/``.bvh.gz`` (MVN or any skeleton ``inference.loaders``
maps by joint names), ``.mvnx`` (an MVN take), ``.c3d``/``.trc`` (markers or joint
centres, ``markers.py``), ``.mot``/``.sto`` (OpenSim coordinates, Rajagopal names, turned
back into segment orientations by inverting ``app.export.opensim``), ``.npz`` (imucap's
truth file, else an AMASS clip). A file that cannot be used raises ``MotionFormatError``:
one line naming the file and what is wrong.
"""

from __future__ import annotations

import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.export.opensim import JOINTS as OS_JOINTS
from app.export.opensim import M_OS, TRANSLATIONS, opensim_default_pose
from app.validate.kinematics import JOINT_INDEX, JOINT_NAMES
from inference.body.body import Body, forward_kinematics
from inference.body.motion import Motion, MotionFormatError
from inference.body.rotations import euler_to_matrix
from inference.body.skeleton import PARENTS, SEGMENT_INDEX, SEGMENTS

REFERENCE_SUFFIXES = (".bvh", ".bvh.gz", ".mvnx", ".c3d", ".trc", ".mot", ".sto", ".npz")


@dataclass
class Reference:
    """t: (T,) s on the reference's clock; joints: (T, 24, 3) joint centres (indexed as
    ``kinematics.JOINT_INDEX``), Z up, m, NaN where the file has none; have_joints: the
    joint names it has; rot: (T, 24, 3, 3) global orientations or None; have_rot: the
    segments whose orientation it has; mapping: lines 'ours <- theirs' to print; frames:
    (T, 24, 3, 3) segment frames its markers define (``frames.py``), for joint angles
    only, or None; have_frames: the segments they cover."""

    path: str
    format: str
    t: np.ndarray
    joints: np.ndarray
    have_joints: set[str]
    rot: np.ndarray | None = None
    have_rot: set[str] = field(default_factory=set)
    mapping: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    frames: np.ndarray | None = None
    have_frames: set[str] = field(default_factory=set)

    @property
    def fps(self) -> float:
        d = np.diff(self.t)
        return float(1.0 / np.median(d)) if len(d) else 0.0

    @property
    def n_frames(self) -> int:
        return int(len(self.t))


def _kind(path: Path) -> str:
    name = path.name.lower()
    for suf in REFERENCE_SUFFIXES:
        if name.endswith(suf):
            return suf.split(".")[1]
    raise MotionFormatError(str(path), f"not a reference file we read ({', '.join(REFERENCE_SUFFIXES)})")


def read_reference(path: str | os.PathLike, body: Body | None = None,
                   static: str | os.PathLike | None = None) -> Reference:
    """The reference in ``path`` (module docstring). ``body``: the subject's bones, for
    a .mot (which has joint angles, not lengths); 1.75 m proportions without it.
    ``static``: a static trial of the same marker set (C3D or TRC) whose landmarks the
    walking trial lacks (``landmarks.with_static``)."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such reference file")
    kind = _kind(p)
    try:
        if kind in ("c3d", "trc"):
            return _from_markers(p, kind, static)
        if kind in ("mot", "sto"):
            return read_mot_reference(p, body or Body.from_height(1.75))
        if kind == "npz" and _is_truth(p):
            return _from_truth(p)
        return _from_motion(p, kind)
    except MotionFormatError:
        raise
    except (ValueError, KeyError, IndexError) as exc:
        raise MotionFormatError(str(p), str(exc) or type(exc).__name__) from None


def _is_truth(p: Path) -> bool:
    try:
        with np.load(p, allow_pickle=False) as z:
            return "format" in z.files
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        why = (str(exc).splitlines() or [type(exc).__name__])[0][:120]
        raise MotionFormatError(str(p), f"not a readable .npz ({why})") from None


def _rotation_reference(path: Path, kind: str, t: np.ndarray, rot: np.ndarray, root: np.ndarray, offsets: np.ndarray,
                        have: set[str], mapping: list[str], notes: list[str] | None = None) -> Reference:
    J = forward_kinematics(rot, root, offsets)
    # a joint's place along its parent segment is set by the parent's orientation
    have_joints = {JOINT_NAMES[s] for s in have}
    have_joints |= {JOINT_NAMES[SEGMENTS[i]] for i in range(1, len(SEGMENTS)) if SEGMENTS[PARENTS[i]] in have}
    return Reference(str(path), kind, t, J, have_joints, rot, set(have), mapping, notes or [])


def _from_motion(p: Path, kind: str) -> Reference:
    from inference.loaders import load_motion

    m: Motion = load_motion(p)
    mapping: list[str] = []
    if kind in ("bvh", "mvnx"):
        from inference.loaders.joint_maps import BVH_MAPS, MVN

        jmap = next((j for j in (*BVH_MAPS, MVN) if j.name == m.meta.get("skeleton")), None)
        if jmap is not None:
            mapping = [f"{ours} <- {theirs}" for ours, theirs in jmap.segments.items()]
            mapping.insert(0, f"skeleton {jmap.name}")
            have = set(jmap.segments)
        else:
            have = set(SEGMENTS)
    else:
        have = set(SEGMENTS)
    start = float(m.meta.get("first_index", 0)) / m.fps
    t = start + np.arange(m.n_frames) / m.fps
    return _rotation_reference(p, kind, t, m.rot, m.root, m.body.offsets, have, mapping)


def _from_truth(p: Path) -> Reference:
    from app.capture.simulate import read_truth

    tr = read_truth(p)
    t = np.arange(len(tr.rot)) / tr.fps
    note = f"truth clock: frame 0 at session time {tr.t0:.3f} s"
    return _rotation_reference(p, "truth", t, tr.rot, tr.root, tr.offsets, set(SEGMENTS), [], [note])


def _from_markers(p: Path, kind: str, static: str | os.PathLike | None = None) -> Reference:
    from app.validate.landmarks import with_static
    from app.validate.markers import Markers, marker_reference, read_c3d, read_trc

    def read(q: Path) -> Markers:
        return read_c3d(q) if q.name.lower().endswith(".c3d") else read_trc(q)

    m = read(p)
    if not np.all(np.isfinite(m.t)) or np.any(np.diff(m.t) <= 0):
        raise MotionFormatError(str(p), "frame times do not increase")
    extra: list[str] = []
    if static is not None:
        s = read(Path(static))
        pos, labels, extra = with_static(m.pos, m.labels, s.pos, s.labels)
        m = Markers(m.path, m.t, pos, labels, m.rate)
    J, have, mapping, frames, notes = marker_reference(m)
    R = None
    if frames:
        R = np.broadcast_to(np.eye(3), (len(m.t), len(SEGMENTS), 3, 3)).copy()
        for seg, f in frames.items():
            R[:, SEGMENT_INDEX[seg]] = f
    return Reference(str(p), kind, m.t, J, have, None, set(), mapping + extra, notes, R, set(frames))


# ---------------------------------------------------------------------------- OpenSim .mot/.sto


def _parse_storage(p: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    spath = str(p)
    try:
        lines = p.read_text(errors="strict").splitlines()
    except UnicodeDecodeError:
        raise MotionFormatError(spath, "not a text file (an OpenSim storage file is text)") from None
    header: dict[str, str] = {}
    end = next((i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader"), None)
    if end is None:
        raise MotionFormatError(spath, "no 'endheader' line: not an OpenSim .mot/.sto")
    for ln in lines[:end]:
        if "=" in ln:
            k, v = ln.split("=", 1)
            header[k.strip()] = v.strip()
    if end + 1 >= len(lines):
        raise MotionFormatError(spath, "no column labels after 'endheader'", end + 1)
    labels = [s.strip() for s in lines[end + 1].split("\t") if s.strip()] or lines[end + 1].split()
    if not labels or labels[0].lower() != "time":
        raise MotionFormatError(spath, f"the first column is {labels[0] if labels else 'missing'!r}, not 'time'",
                                end + 2)
    rows = []
    for no, ln in enumerate(lines[end + 2:], start=end + 3):
        if not ln.strip():
            continue
        cells = ln.split()
        if len(cells) != len(labels):
            raise MotionFormatError(spath, f"{len(cells)} values for {len(labels)} columns", no)
        try:
            rows.append([float(c) for c in cells])
        except ValueError as exc:
            raise MotionFormatError(spath, f"not a number ({exc})", no) from None
    if len(rows) < 2:
        raise MotionFormatError(spath, f"{len(rows)} data row(s); at least 2 are needed")
    data = np.array(rows)
    if not np.all(np.isfinite(data)):
        raise MotionFormatError(spath, "NaN or infinite values")
    if np.any(np.diff(data[:, 0]) <= 0):
        raise MotionFormatError(spath, "the time column does not increase")
    return header, labels, data


def read_mot_reference(p: Path, body: Body) -> Reference:
    """An OpenSim motion's coordinates turned back into our segment orientations: the
    inverse of ``app.export.opensim.opensim_coordinates`` (its docstring has the axes).
    The segments the Rajagopal coordinates set (pelvis, thighs, shanks, feet, torso, upper
    arms, forearms) are compared; the rest follow their parents for the joint centres."""
    header, labels, data = _parse_storage(p)
    col = {n: k for k, n in enumerate(labels)}
    scale = 1.0 if header.get("inDegrees", "yes").lower() == "yes" else 180.0 / math.pi
    known = [c for _, _, _, coords in OS_JOINTS for c, _, _ in coords]
    if not any(c in col for c in known):
        raise MotionFormatError(str(p), "none of its columns is an OpenSim coordinate we know (Rajagopal names: "
                                        f"hip_flexion_r, knee_angle_r, ...); columns: {', '.join(labels[1:9])}")
    T = len(data)
    Q = opensim_default_pose()
    G = np.broadcast_to(np.eye(3), (T, len(SEGMENTS), 3, 3)).copy()
    have: set[str] = set()
    mapping = []
    for _, parent, child, coords in OS_JOINTS:
        if not any(c in col for c, _, _ in coords):
            continue
        eul = np.zeros((T, 3))
        for name, k, sign in coords:
            if name in col:
                eul[:, k] = sign * np.deg2rad(data[:, col[name]] * scale)
        L = euler_to_matrix(eul, "ZXY")
        ci = SEGMENT_INDEX[child]
        G[:, ci] = L if parent is None else G[:, SEGMENT_INDEX[parent]] @ L
        have.add(child)
        mapping.append(f"{child} <- {', '.join(c for c, _, _ in coords if c in col)}")
    # our orientation from OpenSim's body frame: G_os = M R Q^T M^T
    R = M_OS.T @ G @ M_OS @ Q
    for i, s in enumerate(SEGMENTS):  # the segments no coordinate sets follow their parent
        if s not in have and PARENTS[i] >= 0:
            R[:, i] = R[:, PARENTS[i]] @ Q[PARENTS[i]].T @ Q[i]
    root = np.zeros((T, 3))
    if all(n in col for n in TRANSLATIONS):
        root = np.stack([data[:, col[n]] for n in TRANSLATIONS], axis=-1) @ M_OS
    ref = _rotation_reference(p, "mot", data[:, 0], R, root, body.offsets, have, mapping)
    ref.notes.append("joint centres from the subject's bone lengths (a .mot has none)")
    return ref


__all__ = ["Reference", "REFERENCE_SUFFIXES", "read_reference", "read_mot_reference", "JOINT_INDEX"]
