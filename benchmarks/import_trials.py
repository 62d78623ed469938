"""How well ``imucap import --calibration-trial`` calibrates a walk trial that has no still start.

Synthesized Movella DOT sessions (``sim_devices.dot_session``: an N-pose trial, a leg cycle per
leg, a walk that starts after its first steps; seven sensors mounted +X up, +Z lateral with
10 deg mounting errors, MTw-class noise, every sensor a random heading reference per trial),
per seed:

- **headings**: each sensor's recovered R_WG of the walk against the drawn one (angle about
  the vertical), calibrated from the N-pose trial alone, and from the N-pose and leg cycles;
- **bones** (``--bones``): the calibrated sensors' bone orientations over the walk against the
  truth (mean angle over the seven segments), and the model's GA after a replay (1 step),
  for the same walk imported three ways: with its still start (the walk as recorded from
  the stand, calibrated on that stand and its gait, ``--calibration walk``), without it
  calibrated from the N-pose trial, and from the N-pose and leg-cycle trials.

    .venv/bin/python benchmarks/import_trials.py --seeds 20 [--bones] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from app.importing import import_paths  # noqa: E402
from app.importing.trials import import_with_calibration  # noqa: E402
from app.recording import read_recording  # noqa: E402
from drivers.xsens_export import read_exports  # noqa: E402
from inference.body.conventions import yaw_of  # noqa: E402
from inference.body.rotations import matrix_angle_between  # noqa: E402
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX  # noqa: E402
from sim_devices.dot_session import SITES, synthesize_dot_session, synthesize_trial  # noqa: E402
from sim_devices.xsens_export import stand_walk_stand  # noqa: E402

CUT = 240  # frames of the still-start walk before the cut walk trial starts (2 s stand, 0.5 s blend, 1.5 s walking)


def heading_errors(rec_path: Path, R_WG: np.ndarray) -> dict[str, float]:
    cal = read_recording(rec_path).calibrations[0][1]
    return {s: float(np.degrees(yaw_of(cal.R_WG[k] @ R_WG[SITES.index(s)].T))) for k, s in enumerate(cal.sites)}


def _truth_index(rec_path: Path, files: list[Path], res) -> float:
    """The truth's frame (60 Hz) of the recording's frame 0."""
    return (res.grid_t0 - float(read_exports(files)[0].t[0])) * 60.0


def bone_and_ga(rec_path: Path, truth_rot: np.ndarray, first: float, skip: int = 0) -> tuple[float, float]:
    """Mean angle (deg) of the calibrated sensors' bones and the replayed model's GA to the
    truth, over the recording's frames from ``skip``."""
    from app.export.formats import body_for_recording
    from app.replay import ReplaySettings, build_replay_poser, replay_recording
    from inference.metrics.errors import global_angle_error

    rec = read_recording(rec_path)
    cal = rec.calibrations[0][1]
    quat = np.stack([rec.raw[s]["quat"] for s in rec.sites], axis=1).astype(np.float64)
    acc = np.stack([rec.raw[s]["acc"] for s in rec.sites], axis=1).astype(np.float64)
    R_WB, _ = cal.apply(quat, acc=acc)
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in rec.sites]
    idx = np.clip(np.rint(first + np.arange(len(R_WB))).astype(int), 0, len(truth_rot) - 1)
    ok = np.all(np.isfinite(R_WB), axis=(-1, -2))
    ok[:skip] = False
    err = np.degrees(matrix_angle_between(np.where(ok[..., None, None], R_WB, np.eye(3)), truth_rot[idx][:, seg]))
    bones = float(err[ok].mean())
    body, _ = body_for_recording(rec.metadata)
    built = build_replay_poser(rec, ReplaySettings(steps=1), body)
    res = replay_recording(rec, built.poser, causal=built.causal)
    t = np.array([p.t for p in res.poses])
    rot = np.stack([p.pose.rot for p in res.poses])
    keep = t * 60.0 >= skip
    ti = np.clip(np.rint(first + t * 60.0).astype(int), 0, len(truth_rot) - 1)
    return bones, float(global_angle_error(rot[keep], truth_rot[ti[keep]]).mean())


def run(seed: int, bones: bool = False) -> dict:
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        s = synthesize_dot_session(tmp / "s", seed=seed)
        walk = s.trials["walk_001"]
        for label, cal in (("npose", ["npose"]), ("npose+legs", ["npose", "legcycle_left", "legcycle_right"])):
            res = import_with_calibration([walk.folder], [s.trials[c].folder for c in cal], tmp / f"{label}.h5",
                                          reconstruct=False)
            out[label] = {"headings": heading_errors(tmp / f"{label}.h5", walk.R_WG)}
            if bones:
                out[label]["bones"], out[label]["ga"] = bone_and_ga(
                    tmp / f"{label}.h5", walk.motion.resample(60.0).rot, _truth_index(tmp, walk.files, res))
        if bones:  # the same walk as recorded from its stand, calibrated on its own
            whole = stand_walk_stand(walk_s=7.0, stand_s=2.0, end_s=0.7, seed=seed * 10)
            t = synthesize_trial(whole, tmp / "s", "walk_still_start", "walk", seed, 1000 * seed + 99,
                                 _noise())
            res = import_paths([t.folder], tmp / "still.h5", calibration="walk", reconstruct=False)
            out["still start"] = {"headings": heading_errors(tmp / "still.h5", t.R_WG)}
            first = _truth_index(tmp, t.files, res)
            out["still start"]["bones"], out["still start"]["ga"] = bone_and_ga(
                tmp / "still.h5", whole.resample(60.0).rot, first, skip=int(round(CUT - first)))
    return out


def _noise():
    from dataclasses import replace

    from inference.signals.synthesis import NoiseModel

    return replace(NoiseModel.typical(), mounting_deg=10.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--bones", action="store_true", help="also bones and the model's GA, with a still start too")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = []
    for seed in range(args.seeds):
        r = run(seed, args.bones)
        rows.append(r)
        if not args.json:
            print(f"seed {seed:2d}: " + "; ".join(
                f"{k}: max {max(abs(v) for v in r[k]['headings'].values()):.1f}"
                + (f", bones {r[k]['bones']:.1f}, GA {r[k]['ga']:.1f}" if "bones" in r[k] else "")
                for k in r), flush=True)
    summary = {}
    for k in rows[0]:
        h = np.array([[abs(r[k]["headings"][s]) for s in SITES] for r in rows])
        summary[k] = {"heading_median_deg": round(float(np.median(h)), 2), "heading_max_deg": round(float(h.max()), 2),
                      "per_site_max_deg": {s: round(float(h[:, j].max()), 2) for j, s in enumerate(SITES)}}
        if "bones" in rows[0][k]:
            summary[k]["bones_deg"] = round(float(np.mean([r[k]["bones"] for r in rows])), 2)
            summary[k]["ga_deg"] = round(float(np.mean([r[k]["ga"] for r in rows])), 2)
    if args.json:
        print(json.dumps({"seeds": args.seeds, "summary": summary}))
    else:
        print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
