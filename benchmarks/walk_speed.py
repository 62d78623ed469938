"""The reconstructed walking speed on a synthesized walk, with and without the shank stride scaling.

    .venv/bin/python benchmarks/walk_speed.py [--motion walk] [--file MOTION] [--seeds 0 3] [--seconds 20] [--json]

The shank stride scaling (``inference/poser/stride.py``) anchors each stride at foot-flat, where a real
ankle is still. The procedural walk (``sim_devices/motions.py``) rolls its stance foot heel to toe without
lying flat, so its ankle moves through the frames labelled foot-flat; this prints, per seed, the truth's
mean horizontal root speed, the reconstruction's with the scaling (the default) and without, and the
truth's ankle speed over its foot-flat frames (a walk whose feet lie flat: a few cm/s). NOTES.md,
"The procedural walk's stance foot".
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from app.report.events import FOOT_POINTS
from inference.body.skeleton import SEGMENT_INDEX
from inference.evaluation.runner import SIX, clip_input, clip_poser, resolve_models
from inference.loaders import load_motion
from inference.poser.poser import reconstruct_offline
from inference.signals.resample import FPS_MODEL
from inference.signals.synthesis import kinematics
from sim_devices.motions import generate


def root_speed(root: np.ndarray, fps: float) -> float:
    """Mean horizontal speed of a root path (m/s)."""
    return float(np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1).mean() * fps)


def flat_ankle_speed(motion) -> float:
    """Median ankle speed (m/s) over the frames where a foot's heel and toe points are both in contact."""
    k = kinematics(motion)
    speeds = []
    for side, (heel, toe) in FOOT_POINTS.items():
        ankle = k.joints[:, SEGMENT_INDEX[f"{side}_foot"]]
        v = np.linalg.norm(np.gradient(ankle, 1.0 / k.fps, axis=0), axis=1)
        speeds.append(v[k.contacts[:, heel] & k.contacts[:, toe]])
    return float(np.median(np.concatenate(speeds)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--motion", default="walk", help="a procedural motion (sim_devices.motions)")
    ap.add_argument("--file", help="a motion file instead (its first --seconds)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 3])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--model", default="diffusion")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    model = resolve_models([a.model])[a.model]
    rows = []
    for seed in a.seeds:
        if a.file:
            m = load_motion(a.file)
            m = m.slice(0, min(m.n_frames, int(a.seconds * m.fps) + 1))
        else:
            m = generate(a.motion, seconds=a.seconds, seed=seed)
        inp = clip_input(m, SIX, seed=seed)
        row = {"seed": seed, "truth_mps": round(root_speed(inp.root, FPS_MODEL), 3),
               "flat_ankle_mps": round(flat_ankle_speed(m), 3)}
        for key, scale in (("scaled_mps", True), ("unscaled_mps", False)):
            rec = reconstruct_offline(clip_poser(model, inp, seed=seed, stride_scale=scale), inp.features, inp.mask)
            row[key] = round(root_speed(rec.root, FPS_MODEL), 3)
        rows.append(row)
        if not a.json:
            print(row, flush=True)
    if a.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
