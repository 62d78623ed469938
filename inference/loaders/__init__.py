"""Motion files -> `Motion`: BVH, ASF/AMC, AMASS .npz (plain or gzipped) and Xsens MVN takes (.mvnx).

`load_motion` picks the reader from the file name; `find_motion_files` walks folders the
way `--data PATH...` on the CLI means them."""

from __future__ import annotations

from pathlib import Path

from inference.body.motion import Motion, MotionFormatError

MOTION_SUFFIXES = (".bvh", ".bvh.gz", ".amc", ".amc.gz", ".npz", ".mvnx")


def _kind(path: Path) -> str | None:
    name = path.name.lower()
    for suf in MOTION_SUFFIXES:
        if name.endswith(suf):
            return suf.split(".")[1]
    return None


# Beyond these a clip is a broken file or wrong units, not a person: the fastest sprinters
# reach ~12 m/s, and adult and child heights lie well inside 0.5-3 m.
MAX_ROOT_SPEED = 50.0  # m/s between two frames
MAX_ROOT_DISTANCE = 10_000.0  # m from the origin
BODY_HEIGHT_RANGE = (0.5, 3.0)  # m


def load_motion(path: str | Path) -> Motion:
    """Load any supported motion file, retargeted to our body and world, floor aligned.

    Whatever loads is also checked for values no person produces (``check_motion``): a
    NaN or a root that jumps a hundred metres would otherwise become training targets,
    synthesized signals and metrics without a word, so it is a MotionFormatError that
    names the file."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such motion file")
    kind = _kind(path)
    try:
        if kind == "bvh":
            from inference.loaders.bvh import load_bvh

            motion = load_bvh(path)
        elif kind == "amc":
            from inference.loaders.asf_amc import load_amc

            motion = load_amc(path)
        elif kind == "npz":
            from inference.loaders.amass import load_amass

            motion = load_amass(path)
        elif kind == "mvnx":
            from inference.loaders.mvnx import load_mvnx

            motion = load_mvnx(path)
        else:
            raise MotionFormatError(str(path), f"unknown motion format; supported: {', '.join(MOTION_SUFFIXES)}")
    except MotionFormatError:
        raise
    except ValueError as exc:  # e.g. Motion's own checks, which do not know the file
        raise MotionFormatError(str(path), str(exc)) from None
    check_motion(motion, str(path))
    return motion


def check_motion(motion: Motion, path: str) -> None:
    """Raise MotionFormatError naming ``path`` for values that cannot be a person's motion:
    non-finite rotations, root or bone offsets, rotations that are not rotations, a body
    height outside ``BODY_HEIGHT_RANGE``, a root faster than ``MAX_ROOT_SPEED`` or farther
    than ``MAX_ROOT_DISTANCE`` from the origin."""
    import numpy as np

    rot, root, offsets = motion.rot, motion.root, np.asarray(motion.body.offsets)
    for what, arr in (("rotations", rot), ("root positions", root), ("bone offsets", offsets)):
        bad = ~np.isfinite(arr)
        if bad.any():
            where = f" (first at frame {int(np.argwhere(bad)[0][0])})" if arr is not offsets else ""
            raise MotionFormatError(path, f"{what} contain NaN or infinite values{where}")
    height = float(motion.body.height)
    lo, hi = BODY_HEIGHT_RANGE
    if not lo <= height <= hi:
        raise MotionFormatError(path, f"body height {height:.3g} m is outside {lo}-{hi} m (wrong units in the file?)")
    ortho = np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)).max(axis=(-1, -2))
    det = np.linalg.det(rot)
    off = (ortho > 1e-3) | (np.abs(det - 1.0) > 1e-3)
    if off.any():
        i, j = (int(v) for v in np.argwhere(off)[0])
        raise MotionFormatError(path, f"frame {i}: the orientation of segment {j} is not a rotation")
    far = np.linalg.norm(root, axis=-1)
    if far.max() > MAX_ROOT_DISTANCE:
        i = int(np.argmax(far))
        raise MotionFormatError(path, f"frame {i}: root {far[i]:.3g} m from the origin (wrong units in the file?)")
    if len(root) > 1:
        speed = np.linalg.norm(np.diff(root, axis=0), axis=-1) * motion.fps
        if speed.max() > MAX_ROOT_SPEED:
            i = int(np.argmax(speed))
            raise MotionFormatError(path, f"frames {i}-{i + 1}: the root moves at {speed[i]:.3g} m/s "
                                          f"(more than {MAX_ROOT_SPEED:g}: a glitch or wrong units in the file)")


def find_motion_files(paths: list[str | Path] | str | Path) -> list[Path]:
    """Motion files under the given files/folders (recursive), sorted, without duplicates."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    out: set[Path] = set()
    for p in map(Path, paths):
        if p.is_dir():
            out.update(f for f in p.rglob("*") if f.is_file() and _kind(f))
        elif p.is_file():
            if not _kind(p):
                raise MotionFormatError(str(p), f"not a motion file ({', '.join(MOTION_SUFFIXES)})")
            out.add(p)
        else:
            raise FileNotFoundError(f"{p}: no such file or folder")
    return sorted(out)


__all__ = ["load_motion", "check_motion", "find_motion_files", "Motion", "MotionFormatError", "MOTION_SUFFIXES"]
