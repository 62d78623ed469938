"""How well ``imucap import`` finds each sensor's heading from a logged walk.

Simulated MT Manager exports (``sim_devices.xsens_export``) of a stand, a walk straight
ahead and a stand, each sensor's reference frame turned by a heading drawn uniformly in
+-60 deg and strapped on with a mounting rotation up to 20 deg (plus the typical MTw-class
noise), imported with ``--calibration walk``; per sensor, the angle about the vertical
between the recovered sensor-to-world rotation and the drawn one.

    .venv/bin/python benchmarks/import_heading.py [--seeds 20] [--calibration walk] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from app.cli.importing import import_paths  # noqa: E402
from app.recording import read_recording  # noqa: E402
from inference.body.conventions import yaw_of  # noqa: E402
from inference.signals.synthesis import NoiseModel, synthesize  # noqa: E402
from sim_devices.xsens_export import stand_walk_stand, write_mtmanager_exports  # noqa: E402

SITES = ("pelvis", "torso", "head", "l_wrist", "r_wrist", "l_thigh", "r_thigh", "l_shank", "r_shank")
IDS = {s: f"00B4{0x21E6 + k:04X}" for k, s in enumerate(SITES)}


def yaw_deg(R: np.ndarray) -> np.ndarray:
    return np.degrees(yaw_of(R))


def simulated_walk_exports(folder: Path, seed: int, heading_deg: float = 60.0, mounting_deg: float = 20.0,
                           offsets: dict[str, float] | None = None) -> np.ndarray:
    """Write one simulated walk's MT Manager exports into ``folder``; returns each site's
    drawn R_WG (S,3,3), the world's X the subject's forward. ``offsets``: site -> deg,
    turns that sensor's frame by that much more (a sensor whose heading is off)."""
    motion = stand_walk_stand(walk_s=6.0, seed=seed)
    noise = replace(NoiseModel.typical(), heading_deg=heading_deg, mounting_deg=mounting_deg)
    sig = synthesize(motion, noise, rng=seed, sites=SITES)
    R_WG = np.array(sig.meta["R_WG"], float)
    if offsets:
        from inference.body.rotations import matrix_about_axis, matrix_to_quat, quat_multiply

        quat = sig.quat.copy()
        for site, deg in offsets.items():
            k = SITES.index(site)
            Rz = matrix_about_axis(np.array([0.0, 0.0, 1.0]), np.deg2rad(deg))
            quat[:, k] = quat_multiply(matrix_to_quat(Rz.T), quat[:, k])  # G turned by +deg: R_GS' = Rz^T R_GS
            R_WG[k] = R_WG[k] @ Rz
        sig = replace(sig, quat=quat)
    write_mtmanager_exports(sig, folder, IDS)
    return R_WG


def heading_errors(rec_path: Path, R_WG_true: np.ndarray) -> dict[str, float]:
    """site -> recovered heading minus drawn heading (deg, signed)."""
    rec = read_recording(rec_path)
    cal = rec.calibrations[0][1]
    out = {}
    for k, s in enumerate(rec.sites):
        d = yaw_deg(cal.R_WG[k] @ R_WG_true[SITES.index(s)].T)
        out[s] = float((d + 180.0) % 360.0 - 180.0)
    return out


def run(seed: int, calibration: str = "walk", offsets: dict[str, float] | None = None) -> tuple[dict, dict]:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "exports"
        R = simulated_walk_exports(folder, seed, offsets=offsets)
        res = import_paths([folder], Path(tmp) / "rec.h5", mapping={i: s for s, i in IDS.items()},
                           calibration=calibration, reconstruct=False)
        return heading_errors(Path(tmp) / "rec.h5", R), res.calibration


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--calibration", default="walk", choices=("walk", "standing", "auto"))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for seed in range(args.seeds):
        err, _ = run(seed, args.calibration)
        rows.append(err)
        if not args.json:
            print(f"seed {seed:2d}: " + " ".join(f"{s} {e:+5.1f}" for s, e in err.items()), flush=True)
    table = np.array([[abs(r[s]) for s in SITES] for r in rows])
    summary = {s: {"median": round(float(np.median(table[:, k])), 2), "max": round(float(table[:, k].max()), 2)}
               for k, s in enumerate(SITES)}
    if args.json:
        print(json.dumps({"seeds": args.seeds, "calibration": args.calibration, "sites": summary}))
        return 0
    print(f"\n| site | median abs error (deg) | max over {args.seeds} seeds |\n|---|---|---|")
    for s in SITES:
        print(f"| {s} | {summary[s]['median']:.1f} | {summary[s]['max']:.1f} |")
    print(f"| all | {np.median(table):.1f} | {table.max():.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
