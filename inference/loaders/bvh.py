"""BVH reader (plain or gzipped) for the Bandai 22-joint files, CMU-style 31-joint files
and other skeletons with a known joint map.

The parser keeps line numbers so a malformed file is reported where it breaks.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from inference.body.body import ANKLE_Z, HIP_Z
from inference.body.motion import Motion, MotionFormatError
from inference.body.rotations import euler_to_matrix, matrix_angle_between
from inference.loaders.joint_maps import match_joint_map
from inference.loaders.retarget import JointMap, SourceSkeleton, detect_up_axis, pick_scale, retarget, world_map
from inference.loaders.text import read_text_lines

# units a BVH may be in; chosen by the resulting body height (BVH does not say)
BVH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "cmu": 0.056444}


class _Tokens:
    """Whitespace tokens with the line each came from."""

    def __init__(self, path: str, lines: list[str]):
        self.path = path
        self.items: list[tuple[str, int]] = []
        self.pos = 0
        self.lines = lines

    def fill_until_motion(self) -> int:
        for n, line in enumerate(self.lines, start=1):
            if line.strip().upper() == "MOTION":
                return n
            for tok in line.split():
                self.items.append((tok, n))
        raise MotionFormatError(self.path, "no MOTION section (file truncated?)", len(self.lines))

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise MotionFormatError(self.path, f"unexpected end of hierarchy, expected {what}", last)
        tok = self.items[self.pos]
        self.pos += 1
        return tok

    def expect(self, word: str) -> int:
        tok, line = self.next(word)
        if tok != word:
            raise MotionFormatError(self.path, f"expected {word!r}, found {tok!r}", line)
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            v = float(tok)
        except ValueError:
            raise MotionFormatError(self.path, f"expected a number for {what}, found {tok!r}", line) from None
        if not np.isfinite(v):
            raise MotionFormatError(self.path, f"{what} is not finite ({tok})", line)
        return v


_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


def parse_bvh(path: str | Path) -> SourceSkeleton:
    """Parse a BVH file into a SourceSkeleton (source units, source axes)."""
    path = str(path)
    lines = read_text_lines(path)
    tk = _Tokens(path, lines)
    motion_line = tk.fill_until_motion()
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[list[str]] = []
    end_sites: dict[int, np.ndarray] = {}

    tok, line = tk.next("HIERARCHY")
    if tok != "HIERARCHY":
        raise MotionFormatError(path, f"not a BVH file: starts with {tok!r}", line)
    stack: list[int] = []
    tok, line = tk.next("ROOT")
    if tok != "ROOT":
        raise MotionFormatError(path, f"expected ROOT, found {tok!r}", line)
    kind = "ROOT"
    while True:
        if kind in ("ROOT", "JOINT"):
            name, line = tk.next("joint name")
            if name in names:
                raise MotionFormatError(path, f"joint {name!r} defined twice", line)
            tk.expect("{")
            tk.expect("OFFSET")
            off = np.array([tk.number("OFFSET x"), tk.number("OFFSET y"), tk.number("OFFSET z")])
            tk.expect("CHANNELS")
            nch_tok, nch_line = tk.next("channel count")
            try:
                nch = int(nch_tok)
            except ValueError:
                raise MotionFormatError(path, f"bad channel count {nch_tok!r}", nch_line) from None
            chans = []
            for _ in range(nch):
                c, cl = tk.next("channel name")
                if c not in _ROT and c not in _POS:
                    raise MotionFormatError(path, f"unknown channel {c!r} in joint {name!r}", cl)
                chans.append(c)
            names.append(name)
            parents.append(stack[-1] if stack else -1)
            offsets.append(off)
            channels.append(chans)
            stack.append(len(names) - 1)
        elif kind == "End":
            tk.expect("Site")
            tk.expect("{")
            tk.expect("OFFSET")
            end = np.array([tk.number("End Site x"), tk.number("End Site y"), tk.number("End Site z")])
            tk.expect("}")
            end_sites[stack[-1]] = end
        # after a joint header or end site: children or closing braces
        while True:
            tok, line = tk.next("JOINT, End Site or }")
            if tok == "}":
                if not stack:
                    raise MotionFormatError(path, "unbalanced '}'", line)
                stack.pop()
                if not stack:
                    break
                continue
            if tok in ("JOINT", "End"):
                kind = tok
                break
            raise MotionFormatError(path, f"expected JOINT, End Site or '}}', found {tok!r}", line)
        if not stack:
            break

    # MOTION section
    rest = lines[motion_line:]
    if len(rest) < 2:
        raise MotionFormatError(path, "MOTION section has no Frames/Frame Time lines", motion_line)
    fline, tline = rest[0].strip(), rest[1].strip()
    try:
        n_frames = int(fline.split(":")[1])
        frame_time = float(tline.split(":")[1])
    except (IndexError, ValueError):
        raise MotionFormatError(path, "expected 'Frames: N' and 'Frame Time: dt'", motion_line + 1) from None
    if n_frames < 1:
        raise MotionFormatError(path, f"header says {n_frames} frames: a motion needs at least one", motion_line + 1)
    if frame_time <= 0 or not np.isfinite(frame_time):
        raise MotionFormatError(path, f"bad frame time {frame_time}", motion_line + 2)
    n_chan = sum(len(c) for c in channels)
    data_lines = [ln for ln in rest[2:] if ln.strip()]
    if len(data_lines) < n_frames:
        raise MotionFormatError(
            path, f"file truncated: header says {n_frames} frames, found {len(data_lines)}",
            motion_line + 2 + len(data_lines),
        )
    first_data_line = motion_line + 3
    rows = [ln.split() for ln in data_lines[:n_frames]]
    for f, parts in enumerate(rows):
        if len(parts) != n_chan:
            raise MotionFormatError(
                path, f"frame {f} has {len(parts)} values, the hierarchy declares {n_chan} channels",
                first_data_line + f,
            )
    try:
        data = np.array(rows, dtype=np.float64)
    except ValueError:
        for f, parts in enumerate(rows):
            try:
                [float(x) for x in parts]
            except ValueError:
                raise MotionFormatError(path, f"frame {f} has a value that is not a number",
                                        first_data_line + f) from None
        raise
    if not np.all(np.isfinite(data)):
        f = int(np.where(~np.isfinite(data).all(axis=1))[0][0])
        raise MotionFormatError(path, f"frame {f} contains NaN or infinite values", first_data_line + f)

    # forward kinematics in source units and axes
    J = len(names)
    glob = np.zeros((n_frames, J, 3, 3))
    pos = np.zeros((n_frames, J, 3))
    rest_pos = np.zeros((J, 3))
    starts = np.cumsum([0] + [len(c) for c in channels])
    col_of = [{c: int(starts[j]) + k for k, c in enumerate(chans)} for j, chans in enumerate(channels)]
    # each joint's local rotation, intrinsic in channel order: one conversion per channel order for
    # all the joints that share it (a file's joints mostly do), not one per joint
    by_order: dict[str, list[int]] = {}
    for j, chans in enumerate(channels):
        rot_names = [c for c in chans if c in _ROT]
        if rot_names:
            by_order.setdefault("".join(_ROT[c] for c in rot_names), []).append(j)
    locals_: dict[int, np.ndarray] = {}
    for order, joints in by_order.items():
        cols_rot = [[col_of[j][c] for c in channels[j] if c in _ROT] for j in joints]
        mats = euler_to_matrix(np.deg2rad(data[:, cols_rot]), order)  # (T, joints, 3, 3)
        for k, j in enumerate(joints):
            locals_[j] = mats[:, k]
    for j in range(J):
        cols = col_of[j]
        local = locals_.get(j)
        if local is None:
            local = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        trans = np.broadcast_to(offsets[j], (n_frames, 3)).copy()
        for c, k in _POS.items():
            if c in cols:
                trans[:, k] = data[:, cols[c]]
        p = parents[j]
        if p < 0:
            glob[:, j] = local
            pos[:, j] = trans
            rest_pos[j] = offsets[j]
        else:
            glob[:, j] = glob[:, p] @ local
            pos[:, j] = pos[:, p] + (glob[:, p] @ trans[..., None])[..., 0]
            rest_pos[j] = rest_pos[p] + offsets[j]
    ends = {j: rest_pos[j] + e for j, e in end_sites.items()}
    return SourceSkeleton(names=names, parents=parents, rest=rest_pos, glob=glob, pos=pos,
                          fps=1.0 / frame_time, end_sites=ends)


# frame 0 is taken for a conversion's zero pose when its root is not turned at all and no
# joint that drives a segment of ours is turned further than this (deg): cgspeed's Daz
# files hold each subject's calibration stance there, up to 10.6 deg (subject 08's knee)
_AT_REST_DEG = 15.0


def opens_with_zero_pose(src: SourceSkeleton, jmap: JointMap) -> bool:
    """Whether frame 0 holds the rig's zero pose (a T-pose) rather than the take: a
    captured root is never turned by exactly nothing, nor a captured body a T-pose."""
    if float(np.degrees(matrix_angle_between(src.glob[0, 0], np.eye(3)))) > 1e-3:
        return False
    joints = [src.index(n) for n in jmap.required() if src.parents[src.index(n)] >= 0]
    local = [src.glob[0, src.parents[j]].T @ src.glob[0, j] for j in joints]
    return max(float(np.degrees(matrix_angle_between(R, np.eye(3)))) for R in local) < _AT_REST_DEG


def drop_lead_in(src: SourceSkeleton, jmap: JointMap) -> SourceSkeleton:
    """The take without the frames a conversion put before it (``JointMap.lead_in``):
    they would teach the model a T-pose snapping into motion in 60 ms."""
    n = jmap.lead_in
    if n == 0 or src.glob.shape[0] <= n + 1 or not opens_with_zero_pose(src, jmap):
        return src
    return replace(src, glob=src.glob[n:], pos=src.pos[n:])


def height_in_units(src: SourceSkeleton, jmap: JointMap) -> float:
    """Rough body height in the file's units, from the left leg's bone lengths (hip to
    knee to ankle, Drillis & Contini: 0.491 of height). Bone lengths hold in any pose, so
    neither a take that opens crouched or tumbling (bvh_cgspeed/09_10 read as inches when
    its first frame decided) nor a zero pose that is no pose at all (iClone's vertical
    line) can mislead it, as a head-to-feet distance could."""
    hip, knee, ankle = (src.rest[src.index(jmap.segments[f"l_{s}"])] for s in ("thigh", "shank", "foot"))
    return float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)) / (HIP_Z - ANKLE_Z)


def load_bvh(path: str | Path) -> Motion:
    path = str(path)
    src = parse_bvh(path)
    jmap = match_joint_map(src.names, path)
    src = drop_lead_in(src, jmap)
    meta: dict = {"format": "bvh", "skeleton": jmap.name, "layout": jmap.name}
    if jmap.capture_fps is not None and abs(src.fps - jmap.capture_fps) > 1e-3 * jmap.capture_fps:
        meta["declared_fps"] = src.fps
        src = replace(src, fps=jmap.capture_fps)
    up = detect_up_axis(src, jmap)
    W = world_map(up)
    unit, scale = pick_scale(height_in_units(src, jmap), BVH_UNITS)
    name = Path(path).name.removesuffix(".gz").removesuffix(".bvh")
    return retarget(src, jmap, scale, W, name=name, source=path, meta={**meta, "units": unit})
