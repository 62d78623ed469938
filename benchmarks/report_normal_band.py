"""Build the gait report's comparison band (app/report/normal_band.json) from the motion capture's walks.

    .venv/bin/python benchmarks/report_normal_band.py [--data DIR] [--out app/report/normal_band.json] [--list]

Candidates: Bandai's walks in the "normal" style (dataset 1 and 2), every CMU take (ASF/AMC and the Daz
BVH conversion; the iClone copies of subjects 05 and 06 are left out, the same takes as the Daz files)
and every HDM05 take; each is kept or not by what its own strides say (``app.report.normal``: enough
straight walking strides at an ordinary adult speed). ``--list`` prints the kept trials.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app.report.normal import BAND_FILE, band_from_motions
from inference.loaders import find_motion_files, load_motion
from inference.training.data import data_root

NOTE = ("Mean and SD over trials of the walking strides (straight, 0.8-1.8 m/s) in adult motion capture: "
        "Bandai Namco Research Motion Dataset 1 and 2 'walk normal' (CC BY-NC 4.0), CMU Graphics Lab Motion "
        "Capture Database walks (free, attribution asked); HDM05 (CC BY-SA 3.0) was searched and holds no "
        "walking trial. Not clinical normative data.")


def candidates(root: Path) -> list[Path]:
    bandai = [p for p in find_motion_files([root / "bandai"]) if "_walk_normal_" in p.name]
    cmu = find_motion_files([root / "cmu" / "asf_amc", root / "cmu" / "bvh_cgspeed"])
    hdm = find_motion_files([root / "hdm05"])
    return bandai + cmu + hdm


def motions(paths):
    for p in paths:
        try:
            yield load_motion(p)
        except (ValueError, OSError) as exc:  # a take the loaders refuse is no walk to learn from
            print(f"skip {p.name}: {exc}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=None, help="the motion data (default $IMUCAP_DATA or ../shared/data)")
    ap.add_argument("--out", default=str(BAND_FILE))
    ap.add_argument("--list", action="store_true", help="print the trials kept")
    args = ap.parse_args(argv)
    root = Path(args.data) if args.data else data_root()
    paths = candidates(root)
    band, kept = band_from_motions(motions(paths), NOTE)
    band["candidates"] = len(paths)
    band["kept"] = [k["name"] for k in kept]
    Path(args.out).write_text(json.dumps(band, separators=(",", ":")) + "\n")
    if args.list:
        for k in kept:
            print(json.dumps(k))
    print(json.dumps({"candidates": len(paths), "trials": band["trials"], "strides": band["strides"],
                      "sources": band["sources"], "out": args.out}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
