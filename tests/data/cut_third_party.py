"""How the files under tests/data/third_party were cut from their sources (README.md):
run once by hand, kept for the record; not a test.

    .venv/bin/python tests/data/cut_third_party.py SOURCES_DIR

SOURCES_DIR holds the files as downloaded: walk.c3d (kineticstoolkit data/walk.c3d.zip,
unzipped), Qualisys.c3d (ezc3d test file), Meri-020.mvnx, and OpenSim's
subject01_walk1.trc, subject01_static.trc, subject01_walk1_ik.mot (Gait2392_Simbody).
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path

import ezc3d
import numpy as np

OUT = Path(__file__).resolve().parent / "third_party"


def c3d_points_only(src: Path, dst: Path) -> None:
    """The same points, frames and parameters without the analog channels (force plates,
    EMG: most of the bytes). Written by ezc3d as float, so POINT:SCALE says -1 as the
    header does (readers check the two agree)."""
    c = ezc3d.c3d(str(src))
    p = c["parameters"]
    n = c["data"]["points"].shape[2]
    c["data"]["analogs"] = np.zeros((1, 0, n))
    p["ANALOG"]["USED"]["value"] = [0]
    p["ANALOG"]["RATE"]["value"] = p["POINT"]["RATE"]["value"]
    for k in ("LABELS", "DESCRIPTIONS", "UNITS"):
        if k in p["ANALOG"]:
            p["ANALOG"][k]["value"] = ()
    for k in ("SCALE", "OFFSET"):
        if k in p["ANALOG"]:
            p["ANALOG"][k]["value"] = np.zeros(0)
    p["FORCE_PLATFORM"]["USED"]["value"] = [0]
    p["POINT"]["SCALE"]["value"] = [-1.0]
    c.write(str(dst))


def main(src: Path) -> None:
    OUT.mkdir(exist_ok=True)
    c3d_points_only(src / "walk.c3d", OUT / "vicon_nexus_walk.c3d")
    c3d_points_only(src / "Qualisys.c3d", OUT / "qualisys_walk.c3d")
    shutil.copy(src / "Meri-020.mvnx", OUT / "mvn_meri020.mvnx")
    os_dir = OUT / "opensim_subject01"
    os_dir.mkdir(exist_ok=True)
    shutil.copy(src / "subject01_walk1.trc", os_dir / "subject01_walk1.trc")
    lines = (src / "subject01_static.trc").read_text().split("\n")  # the first 12 frames (0.2 s) of standing
    head, rows, keep = lines[:6], [ln for ln in lines[6:] if ln.strip()], 12
    vals = head[2].split("\t")
    vals[2] = f"{keep:>10d}"
    head[2] = "\t".join(vals)
    (os_dir / "subject01_static.trc").write_text("\n".join(head + rows[:keep]) + "\n")
    lines = (src / "subject01_walk1_ik.mot").read_text().split("\n")  # the rows the walk covers (to 2.5 s)
    end = next(i for i, ln in enumerate(lines) if ln.strip() == "endheader")
    rows = [ln for ln in lines[end + 2:] if ln.strip() and float(ln.split()[0]) <= 2.5 + 1e-9]
    hdr = [re.sub(r"nRows=\d+", f"nRows={len(rows)}", ln) for ln in lines[:end + 1]]
    (os_dir / "subject01_walk1_ik.mot").write_text("\n".join([*hdr, lines[end + 1], *rows]) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
