"""An Xsens MVN take (MVNX export) as motion: MVN's own solution of the full suit, its 23
segments' orientations and positions, retargeted onto our body like any other source.

Why: a lab with MVN takes has, in one file, both the sensors a sparse setup would wear
(``drivers.xsens_export.mvnx`` reads those for ``imucap import``) and the full suit's
answer. Read as motion, the take is truth for a re-run with a few of its sensors, and a
clip for ``imucap evaluate``.

The layout (MVNX version 4, as MVN's schema and a public MVN 2019 take have it; version 3,
MVN Studio 4.x, names the points' positions ``pos_s`` instead of ``pos_b`` and is read the
same way): each ``<segment label="...">`` lists its points in its own frame (metres); a joint is
a point both segments name (``jRightHip`` on Pelvis and at the origin of RightUpperLeg), so
the zero pose follows from the points alone. At zero rotation MVN's body stands in a
T-pose, X forward, Y left, Z up (the file's ``identity`` frame), the world is Z up, and
each ``type="normal"`` frame gives every segment's ``orientation`` (w, x, y, z) and
``position`` (its origin, metres) in that world.

``drivers.xsens_export.mvnx`` streams the same files for their sensors. The two readers
share their few lines of XML plumbing (local tag names, a list of numbers) by copy, not
import: drivers and inference depend on nothing of ours (DESIGN.md).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from inference.body.motion import Motion, MotionFormatError
from inference.body.rotations import quat_to_matrix
from inference.loaders.joint_maps import MVN
from inference.loaders.retarget import SourceSkeleton, retarget, world_map

# MVN's 23 segments and their parents (its kinematic tree, in the file's order)
MVN_PARENTS: dict[str, str | None] = {
    "Pelvis": None, "L5": "Pelvis", "L3": "L5", "T12": "L3", "T8": "T12", "Neck": "T8", "Head": "Neck",
    **{k: v for side in ("Right", "Left") for k, v in (
        (f"{side}Shoulder", "T8"), (f"{side}UpperArm", f"{side}Shoulder"), (f"{side}ForeArm", f"{side}UpperArm"),
        (f"{side}Hand", f"{side}ForeArm"))},
    **{k: v for side in ("Right", "Left") for k, v in (
        (f"{side}UpperLeg", "Pelvis"), (f"{side}LowerLeg", f"{side}UpperLeg"), (f"{side}Foot", f"{side}LowerLeg"),
        (f"{side}Toe", f"{side}Foot"))},
}
# where the leaf segments' bones end (a point on the leaf)
END_POINTS = {"Head": "pTopOfHead", "RightHand": "pRightTopOfHand", "LeftHand": "pLeftTopOfHand",
              "RightToe": "pRightToe", "LeftToe": "pLeftToe"}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _vec(elem: ET.Element | None, n: int) -> np.ndarray | None:
    if elem is None or not elem.text:
        return None
    try:
        v = np.array(elem.text.split(), dtype=float)
    except ValueError:
        return None
    return v if v.size == n and np.all(np.isfinite(v)) else None


def parse_mvnx(path: str | os.PathLike, max_frames: int | None = None) -> tuple[SourceSkeleton, int, int]:
    """(the take's segments as a source skeleton, the first normal frame's index, frames
    held over a skipped index): zero pose from the segments' joint points, global
    rotations and positions from the normal frames (streamed; ``max_frames``: stop reading
    after that many, when only the body is wanted)."""
    spath = os.fspath(path)
    labels: list[str] = []
    points: dict[str, dict[str, np.ndarray]] = {}
    segment: str | None = None
    point: str | None = None
    fps = float("nan")
    quats: list[np.ndarray] = []
    pos: list[np.ndarray] = []
    index: list[int] = []
    open_elems: list[ET.Element] = []
    try:
        for event, elem in ET.iterparse(spath, events=("start", "end")):
            tag = _local(elem.tag)
            if event == "start":
                if not open_elems and tag != "mvnx":
                    raise MotionFormatError(spath, f"not an MVNX file (its root element is <{tag}>)")
                open_elems.append(elem)
                if tag == "subject":
                    try:
                        fps = float(elem.get("frameRate", "nan"))
                    except ValueError:
                        fps = float("nan")
                elif tag == "segment":
                    segment = elem.get("label", "")
                    labels.append(segment)
                    points[segment] = {}
                elif tag == "point":
                    point = elem.get("label", "")
                continue
            open_elems.pop()
            if tag in ("pos_b", "pos_s") and segment is not None and point is not None:
                v = _vec(elem, 3)
                if v is not None:
                    points[segment][point] = v
            elif tag == "segments":
                segment = point = None
            elif tag == "frame":
                if elem.get("type", "normal") == "normal":
                    kids = {_local(c.tag): c for c in elem}
                    q, p = _vec(kids.get("orientation"), 4 * len(labels)), _vec(kids.get("position"), 3 * len(labels))
                    try:
                        k = int(elem.get("index", ""))
                    except ValueError:
                        k = index[-1] + 1 if index else 0
                    if q is not None and p is not None and (not index or k > index[-1]):
                        quats.append(q.reshape(-1, 4))
                        pos.append(p.reshape(-1, 3))
                        index.append(k)
                if open_elems:
                    open_elems[-1].remove(elem)
                if max_frames is not None and len(quats) >= max_frames:
                    break
    except MotionFormatError:
        raise
    except (ET.ParseError, LookupError, ValueError) as exc:
        if len(quats) < 2:
            raise MotionFormatError(spath, f"not a readable MVNX take ({exc})") from None
    missing = [s for s in MVN_PARENTS if s not in points]
    if missing:
        raise MotionFormatError(spath, f"not a full-body MVN take: no segment(s) {', '.join(missing)} "
                                       f"(it has {', '.join(labels) or 'none'})")
    if len(quats) < 2:
        raise MotionFormatError(spath, "fewer than two frames with every segment's orientation and position")
    if not fps > 0:
        raise MotionFormatError(spath, "no frame rate (<subject frameRate=...>)")
    names = list(MVN_PARENTS)
    order = [labels.index(n) for n in names]
    rest = np.zeros((len(names), 3))
    parents = []
    for j, name in enumerate(names):
        parent = MVN_PARENTS[name]
        parents.append(-1 if parent is None else names.index(parent))
        if parent is None:
            continue
        joint = next((k for k, v in points[name].items() if k.startswith("j") and not np.any(v)), None)
        if joint is None or joint not in points[parent]:
            raise MotionFormatError(spath, f"segment {name}: no joint point shared with {parent}")
        rest[j] = rest[parents[-1]] + points[parent][joint]
    end_sites = {names.index(s): rest[names.index(s)] + points[s][p] for s, p in END_POINTS.items() if p in points[s]}
    # a frame MVN left out (its index skipped) holds the one before, so frame k stays at k / fps
    if index[-1] - index[0] + 1 > 2 * len(index):
        raise MotionFormatError(spath, f"frame indices {index[0]}..{index[-1]} for {len(index)} frames: more than "
                                       "half the take is missing")
    at = np.searchsorted(index, np.arange(index[0], index[-1] + 1), side="right") - 1
    Q = np.stack(quats)[at][:, order]
    glob = quat_to_matrix(Q / np.linalg.norm(Q, axis=-1, keepdims=True))
    src = SourceSkeleton(names=names, parents=parents, rest=rest, glob=glob, pos=np.stack(pos)[at][:, order],
                         fps=fps, end_sites=end_sites)
    return src, index[0], len(at) - len(index)


def load_mvnx(path: str | os.PathLike, max_frames: int | None = None) -> Motion:
    """The take as our Motion, in MVN's world (Z up, MVN's heading); ``meta`` keeps the
    first frame's index (``first_index``: frame 0 is at ``first_index / fps`` s of the take,
    as the sensors' times are) and how many frames were held over gaps (``held``).
    ``max_frames``: only the take's first frames, for its body."""
    src, first, held = parse_mvnx(path, max_frames)
    name = Path(path).name.removesuffix(".mvnx")
    return retarget(src, MVN, 1.0, world_map(np.array([0.0, 0.0, 1.0])), name=name, source=os.fspath(path),
                    meta={"format": "mvnx", "skeleton": MVN.name, "layout": MVN.name, "first_index": first,
                          "held": held})


__all__ = ["END_POINTS", "MVN_PARENTS", "load_mvnx", "parse_mvnx"]
