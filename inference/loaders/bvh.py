"""BVH reader (plain or gzipped) for the Bandai 22-joint files, CMU-style 31-joint files
and other skeletons with a known joint map.

The parser keeps line numbers so a malformed file is reported where it breaks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from inference.body.motion import Motion, MotionFormatError
from inference.body.rotations import euler_to_matrix
from inference.loaders.joint_maps import match_joint_map
from inference.loaders.retarget import SourceSkeleton, detect_up_axis, pick_scale, retarget, world_map
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
    col = 0
    for j in range(J):
        chans = channels[j]
        cols = {c: col + k for k, c in enumerate(chans)}
        col += len(chans)
        rot_names = [c for c in chans if c in _ROT]
        if rot_names:
            order = "".join(_ROT[c] for c in rot_names)
            ang = np.deg2rad(data[:, [cols[c] for c in rot_names]])
            local = euler_to_matrix(ang, order)  # intrinsic, in channel order
        else:
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


def load_bvh(path: str | Path) -> Motion:
    path = str(path)
    src = parse_bvh(path)
    jmap = match_joint_map(src.names, path)
    up = detect_up_axis(src, jmap)
    W = world_map(up)
    # height in source units from the animation's first frame (feet to head, /0.87 head ratio)
    head = src.pos[0, src.index(jmap.segments["head"])]
    feet = src.pos[0, [src.index(jmap.segments["l_toes"]), src.index(jmap.segments["r_toes"])]]
    h_units = float(abs((head - feet.mean(axis=0)) @ up)) / 0.85
    unit, scale = pick_scale(h_units, BVH_UNITS)
    name = Path(path).name.removesuffix(".gz").removesuffix(".bvh")
    return retarget(src, jmap, scale, W, name=name, source=path,
                    meta={"format": "bvh", "skeleton": jmap.name, "units": unit})
