"""Acclaim ASF/AMC reader (HDM05, CMU), AMC plain or gzipped.

In Acclaim files each bone's rotation acts at the bone's start, in a local frame given
by the bone's `axis` (C); the AMC values M are rotations about that frame, so the bone's
global rotation is G = G_parent C M C^-1 and its end is start + G (direction * length).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inference.body.motion import Motion, MotionFormatError
from inference.body.rotations import euler_to_matrix, matrix_about_axis
from inference.loaders.joint_maps import ACCLAIM_FPS, ASF, match_joint_map
from inference.loaders.retarget import SourceSkeleton, retarget, world_map
from inference.loaders.text import read_text_lines

INCH = 0.0254
_AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}


@dataclass
class AsfBone:
    name: str
    direction: np.ndarray
    length: float
    axis: np.ndarray  # degrees/radians as in file, converted to radians
    axis_order: str
    dofs: list[str] = field(default_factory=list)
    parent: str = ""


@dataclass
class AsfSkeleton:
    path: str
    length_unit: float
    angle_deg: bool
    root_order: list[str]
    root_axis: str
    root_position: np.ndarray
    root_orientation: np.ndarray
    bones: dict[str, AsfBone]
    order: list[str]  # bones in parent-before-child order, 'root' first

    @property
    def scale(self) -> float:
        """Metres per file length unit (Acclaim lengths are inches divided by `length`)."""
        return INCH / self.length_unit


def _floats(path: str, line_no: int, parts: list[str], n: int, what: str) -> np.ndarray:
    if len(parts) < n:
        raise MotionFormatError(path, f"{what}: expected {n} numbers, found {len(parts)}", line_no)
    try:
        v = np.array([float(p) for p in parts[:n]])
    except ValueError:
        raise MotionFormatError(path, f"{what}: not a number in {parts[:n]}", line_no) from None
    if not np.all(np.isfinite(v)):
        raise MotionFormatError(path, f"{what}: NaN or infinite value", line_no)
    return v


def _word(path: str, line_no: int, parts: list[str], what: str) -> str:
    """The value after a keyword (``angle deg``, ``name lfemur``); a keyword alone on its
    line is a damaged file, not an IndexError."""
    if len(parts) < 2:
        raise MotionFormatError(path, f"{what}: no value after {parts[0]!r}", line_no)
    return parts[1]


ROOT_CHANNELS = ("TX", "TY", "TZ", "RX", "RY", "RZ")


def _axis_order(path: str, line_no: int, word: str) -> str:
    """An Euler axis order (``XYZ``, ``ZYX``...): each axis once, or the rotation it names
    is not one."""
    order = word.upper()
    if sorted(order) != ["X", "Y", "Z"]:
        raise MotionFormatError(path, f"axis order {word!r}: X, Y and Z once each", line_no)
    return order


def parse_asf(path: str | Path) -> AsfSkeleton:
    path = str(path)
    lines = read_text_lines(path)
    section = ""
    length_unit, angle_deg = 1.0, True
    root_order: list[str] = []
    root_axis = "XYZ"
    root_pos = np.zeros(3)
    root_ori = np.zeros(3)
    bones: dict[str, AsfBone] = {}
    cur: dict | None = None
    children: dict[str, list[str]] = {}
    for n, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith(":"):
            parts = line.split()
            section = parts[0][1:]
            continue
        parts = line.split()
        key = parts[0]
        if section == "units":
            if key == "length":
                length_unit = float(_floats(path, n, parts[1:], 1, "units length")[0])
            elif key == "angle":
                angle_deg = _word(path, n, parts, "units angle").lower().startswith("deg")
        elif section == "root":
            if key == "order":
                root_order = [p.upper() for p in parts[1:]]
                bad = [d for d in root_order if d not in ROOT_CHANNELS]
                if bad or len(set(root_order)) != len(root_order) or not {"TX", "TY", "TZ"} <= set(root_order):
                    raise MotionFormatError(path, f"root order {' '.join(root_order)!r}: each of TX TY TZ once, "
                                                  f"rotations from RX RY RZ", n)
            elif key == "axis":
                root_axis = _axis_order(path, n, _word(path, n, parts, "root axis"))
            elif key == "position":
                root_pos = _floats(path, n, parts[1:], 3, "root position")
            elif key == "orientation":
                root_ori = _floats(path, n, parts[1:], 3, "root orientation")
        elif section == "bonedata":
            if key == "begin":
                cur = {"line": n}
            elif key == "end":
                if cur is None or "name" not in cur:
                    raise MotionFormatError(path, "bone block without a name", n)
                ax = cur.get("axis", (np.zeros(3), "XYZ"))
                bones[cur["name"]] = AsfBone(
                    name=cur["name"], direction=cur.get("direction", np.zeros(3)), length=cur.get("length", 0.0),
                    axis=ax[0], axis_order=ax[1], dofs=cur.get("dof", []),
                )
                cur = None
            elif cur is not None:
                if key == "name":
                    cur["name"] = _word(path, n, parts, "bone name")
                elif key == "direction":
                    cur["direction"] = _floats(path, n, parts[1:], 3, "bone direction")
                elif key == "length":
                    cur["length"] = float(_floats(path, n, parts[1:], 1, "bone length")[0])
                elif key == "axis":
                    v = _floats(path, n, parts[1:], 3, "bone axis")
                    cur["axis"] = (v, _axis_order(path, n, parts[4]) if len(parts) > 4 else "XYZ")
                elif key == "dof":
                    dofs = [d.lower() for d in parts[1:]]
                    bad = [d for d in dofs if d not in ("rx", "ry", "rz", "tx", "ty", "tz", "l")]
                    if bad:
                        raise MotionFormatError(path, f"unknown dof {bad}", n)
                    cur["dof"] = dofs
        elif section == "hierarchy":
            if key in ("begin", "end"):
                continue
            children.setdefault(key, []).extend(parts[1:])
            for c in parts[1:]:
                if c not in bones:
                    raise MotionFormatError(path, f"hierarchy names unknown bone {c!r}", n)
                bones[c].parent = key
    if not bones:
        raise MotionFormatError(path, "no :bonedata (not an ASF file?)")
    order = ["root"]
    queue = ["root"]
    while queue:
        b = queue.pop(0)
        for c in children.get(b, []):
            if c in order:  # listed under two parents, or a loop (which would never end)
                raise MotionFormatError(path, f":hierarchy reaches bone {c!r} twice (a loop or two parents)")
            order.append(c)
            queue.append(c)
    orphans = set(bones) - set(order)
    if orphans:
        raise MotionFormatError(path, f"bones not in :hierarchy: {sorted(orphans)}")
    conv = np.deg2rad if angle_deg else (lambda x: x)
    for b in bones.values():
        b.axis = conv(b.axis)
    return AsfSkeleton(path=path, length_unit=length_unit, angle_deg=angle_deg, root_order=root_order,
                       root_axis=root_axis, root_position=root_pos, root_orientation=conv(root_ori),
                       bones=bones, order=order)


def _parse_regular(lines: list[str], ndof: dict[str, int]) -> dict[str, np.ndarray] | None:
    """The values of an AMC whose frames all list the same bones in the same order, one bone a line
    (every file of HDM05 and CMU): each bone's lines are every (bones + 1)-th line, so its values are
    read for all frames in one conversion instead of line by line (two thirds of a CMU take's load).
    None when the file is not so regular or a value is not a finite number: ``parse_amc``'s line by
    line reading then says what and where."""
    start = 0
    while start < len(lines) and (not lines[start].strip() or lines[start].lstrip().startswith(("#", ":"))):
        start += 1
    end = len(lines)
    while end > start and not lines[end - 1].strip():
        end -= 1
    body = lines[start:end]
    if not body or not body[0].strip().isdigit():
        return None
    first = [ln.split(None, 1)[0] for ln in body[1:]]
    n_bones = next((k for k, name in enumerate(first) if name.isdigit()), len(first))
    bones = first[:n_bones]
    stride = n_bones + 1
    if n_bones == 0 or len(set(bones)) != n_bones or len(body) % stride or any(b not in ndof for b in bones):
        return None
    if {b for b in ndof if ndof[b] > 0} - set(bones):
        return None
    T = len(body) // stride
    if T < 2 or not all(ln.strip().isdigit() for ln in body[0::stride]):
        return None
    out: dict[str, np.ndarray] = {}
    for k, b in enumerate(bones):
        rows = body[1 + k::stride]
        head = b + " "
        if not all(ln.startswith(head) for ln in rows):
            return None
        n = len(head)
        try:
            values = np.array(" ".join(ln[n:] for ln in rows).split(), dtype=np.float64)
        except ValueError:
            return None
        if values.size != T * ndof[b]:
            return None
        values = values.reshape(T, ndof[b])
        if not np.isfinite(values).all():
            return None
        if ndof[b] > 0:
            out[b] = values
    return out


def parse_amc(path: str | Path, asf: AsfSkeleton) -> dict[str, np.ndarray]:
    """Per bone (T, n_dof) values in file units, plus 'root' (T, len(root order))."""
    path = str(path)
    lines = read_text_lines(path)
    ndof = {name: len([d for d in b.dofs if d != "l"]) for name, b in asf.bones.items()}
    ndof["root"] = len(asf.root_order) or 6
    regular = _parse_regular(lines, ndof)
    if regular is not None:
        return regular
    # per frame, per bone: the value tokens and the line number; turned into numbers once per
    # bone, for all frames at a time (a number and a finiteness check per value, line by
    # line, were three quarters of a CMU take's load)
    frames: list[dict[str, tuple[list[str], int]]] = []
    frame_lines: list[int] = []
    for n, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#") or line.startswith(":"):
            continue
        parts = line.split()
        if len(parts) == 1 and parts[0].isdigit():
            frames.append({})
            frame_lines.append(n)
            continue
        if not frames:
            raise MotionFormatError(path, f"data before the first frame number: {line[:40]!r}", n)
        name = parts[0]
        if name not in ndof:
            raise MotionFormatError(path, f"unknown bone {name!r} (not in {Path(asf.path).name})", n)
        if len(parts) - 1 != ndof[name]:
            raise MotionFormatError(path, f"bone {name!r} has {len(parts) - 1} values, ASF declares {ndof[name]}", n)
        frames[-1][name] = (parts[1:], n)
    if len(frames) < 2:
        raise MotionFormatError(path, f"only {len(frames)} frame(s) of motion", len(lines))
    expected = {b for b in ndof if ndof[b] > 0}
    # a truncated file ends in a partial frame: report it, keep nothing half-read
    for f, fr in enumerate(frames):
        missing = expected - set(fr)
        if missing:
            where = "last frame is incomplete (file truncated?)" if f == len(frames) - 1 else f"frame {f + 1}"
            raise MotionFormatError(path, f"{where}: no values for {sorted(missing)[:5]}", frame_lines[f])
    out: dict[str, np.ndarray] = {}
    errors: list[tuple[int, str]] = []  # the first line of each bone's bad values: the earliest is reported
    for b in expected:
        rows = [fr[b] for fr in frames]
        try:
            values = np.array([tokens for tokens, _ in rows], dtype=np.float64)
        except ValueError:
            for tokens, n in rows:
                try:
                    [float(t) for t in tokens]
                except ValueError:
                    errors.append((n, f"bone {b!r}: value is not a number"))
                    break
            continue
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            errors.append((rows[int(np.argmax(bad))][1], f"bone {b!r}: NaN or infinite value"))
        out[b] = values
    if errors:
        n, message = min(errors)
        raise MotionFormatError(path, message, n)
    return out


def _dof_rotation(values: np.ndarray, dofs: list[str], angle_deg: bool) -> np.ndarray:
    """Rotation from rx/ry/rz values, applied in the listed order about fixed axes."""
    rot_dofs = [(k, d) for k, d in enumerate([d for d in dofs if d != "l"]) if d.startswith("r")]
    T = values.shape[0]
    if not rot_dofs:
        return np.broadcast_to(np.eye(3), (T, 3, 3))
    ang = values[:, [k for k, _ in rot_dofs]]
    if angle_deg:
        ang = np.deg2rad(ang)
    order = "".join(d[1] for _, d in rot_dofs)  # lowercase = extrinsic
    if len(order) == 3 and len(set(order)) == 3:
        return euler_to_matrix(ang, order)
    # one or two dofs (knee, toes): fixed-axis rotations applied in listed order
    M = np.broadcast_to(np.eye(3), (T, 3, 3))
    for k, ax in enumerate(order):
        M = matrix_about_axis(_AXES[ax], ang[:, k]) @ M
    return M


def to_source_skeleton(asf: AsfSkeleton, amc: dict[str, np.ndarray], fps: float) -> SourceSkeleton:
    T = amc["root"].shape[0]
    names = asf.order
    J = len(names)
    idx = {n: i for i, n in enumerate(names)}
    parents = [-1] + [idx[asf.bones[n].parent] for n in names[1:]]
    glob = np.zeros((T, J, 3, 3))
    pos = np.zeros((T, J, 3))
    rest = np.zeros((J, 3))
    rest_end = np.zeros((J, 3))
    ends = np.zeros((T, J, 3))
    # root
    rv = amc["root"]
    ro = asf.root_order or list(ROOT_CHANNELS)
    tcols = [ro.index(a) for a in ("TX", "TY", "TZ")]
    rdofs = [c.lower() for c in ro if c.startswith("R")]
    rcols = [k for k, c in enumerate(ro) if c.startswith("R")]
    C = euler_to_matrix(asf.root_orientation[None], asf.root_axis.lower())[0]
    M = _dof_rotation(rv[:, rcols], rdofs, asf.angle_deg)
    glob[:, 0] = C @ M @ C.T
    pos[:, 0] = rv[:, tcols] + asf.root_position
    ends[:, 0] = pos[:, 0]
    rest[0] = asf.root_position
    rest_end[0] = rest[0]
    end_sites: dict[int, np.ndarray] = {}
    has_child = set(parents[1:])
    for j in range(1, J):
        b = asf.bones[names[j]]
        p = parents[j]
        C = euler_to_matrix(b.axis[None], b.axis_order.lower())[0]
        vals = amc.get(b.name, np.zeros((T, 0)))
        M = _dof_rotation(vals, b.dofs, asf.angle_deg)
        glob[:, j] = glob[:, p] @ (C @ M @ C.T)
        bone = b.direction * b.length
        pos[:, j] = ends[:, p]
        ends[:, j] = pos[:, j] + (glob[:, j] @ bone)
        rest[j] = rest_end[p]
        rest_end[j] = rest[j] + bone
        if j not in has_child:
            end_sites[j] = rest_end[j]
    return SourceSkeleton(names=names, parents=parents, rest=rest, glob=glob, pos=pos, fps=fps,
                          end_sites=end_sites)


def find_asf(amc_path: Path) -> Path:
    """The skeleton file of an AMC take: HDM05 names takes `HDM_<actor>_...`, the skeleton
    `HDM_<actor>.asf`; otherwise the only .asf beside it."""
    folder = amc_path.parent
    asfs = sorted(folder.glob("*.asf")) + sorted(folder.glob("*.ASF"))
    stem = amc_path.name
    for a in asfs:
        if stem.startswith(a.stem + "_"):
            return a
    if len(asfs) == 1:
        return asfs[0]
    raise MotionFormatError(str(amc_path), f"cannot find its .asf skeleton in {folder} ({len(asfs)} candidates)")


# HDM05 writes the rate after the take number (``HDM_bd_squat_003_120.amc``); CMU names a
# take ``<subject>_<take>.amc`` and writes no rate anywhere, so a lone trailing number is
# a take, never a rate (``01_01.amc`` read as 1 frame/s before this asked for both).
_FPS_IN_NAME = re.compile(r"_\d+_(\d{2,3})\.amc(\.gz)?$", re.IGNORECASE)


def amc_frame_rate(path: str | Path) -> float:
    """Frames per second of an AMC take: from an HDM05-style name, else CMU's 120 Hz (the
    AMC format itself has no field for it)."""
    m = _FPS_IN_NAME.search(Path(path).name)
    return float(m.group(1)) if m else ACCLAIM_FPS


def load_amc(path: str | Path, asf_path: str | Path | None = None, fps: float | None = None) -> Motion:
    path = Path(path)
    asf = parse_asf(asf_path or find_asf(path))
    amc = parse_amc(path, asf)
    if fps is None:
        fps = amc_frame_rate(path)
    src = to_source_skeleton(asf, amc, fps)
    jmap = match_joint_map(src.names, str(path), maps=(ASF,))
    W = world_map(np.array([0.0, 1.0, 0.0]))  # Acclaim is Y-up
    name = path.name.removesuffix(".gz").removesuffix(".amc")
    return retarget(src, jmap, asf.scale, W, name=name, source=str(path),
                    meta={"format": "asf/amc", "skeleton": Path(asf.path).name, "layout": jmap.name,
                          "units": "acclaim"})
