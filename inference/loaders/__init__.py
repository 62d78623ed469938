"""Motion files -> `Motion`: BVH, ASF/AMC and AMASS .npz, plain or gzipped.

`load_motion` picks the reader from the file name; `find_motion_files` walks folders the
way `--data PATH...` on the CLI means them."""

from __future__ import annotations

from pathlib import Path

from inference.body.motion import Motion, MotionFormatError

MOTION_SUFFIXES = (".bvh", ".bvh.gz", ".amc", ".amc.gz", ".npz")


def _kind(path: Path) -> str | None:
    name = path.name.lower()
    for suf in MOTION_SUFFIXES:
        if name.endswith(suf):
            return suf.split(".")[1]
    return None


def load_motion(path: str | Path) -> Motion:
    """Load any supported motion file, retargeted to our body and world, floor aligned."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such motion file")
    kind = _kind(path)
    if kind == "bvh":
        from inference.loaders.bvh import load_bvh

        return load_bvh(path)
    if kind == "amc":
        from inference.loaders.asf_amc import load_amc

        return load_amc(path)
    if kind == "npz":
        from inference.loaders.amass import load_amass

        return load_amass(path)
    raise MotionFormatError(str(path), f"unknown motion format; supported: {', '.join(MOTION_SUFFIXES)}")


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


__all__ = ["load_motion", "find_motion_files", "Motion", "MotionFormatError", "MOTION_SUFFIXES"]
