"""AGRoL's MLP (``inference.model.agrol_mlp``) against our model on the three-point task:
the same held-out clips, the same simulated rig with the same noise draws, the same
metrics, paired bootstrap intervals over clips.

    .venv/bin/python benchmarks/vr_baseline.py --agrol runs/agrol_mlp/agrol_mlp.pt \
        --sets dg,cmu-val,sad --json runs/vr/baseline.json [--markdown runs/vr/baseline.md]

Our model's rows are ``benchmarks/vr_three_point.py``'s "3 points" rows, read from its cache
(``runs/vr/cache``; computed and cached there if absent). The MLP's, per clip:
1. the clip turned to face +X at its start (``face_forward``, as the harness does) and its
   20 Hz truth (``clip_input``);
2. the headset and the two controllers from the simulated rig (``SimVrRig``) at 72 Hz with
   its tracking error and latency (1 mm jitter + 2 mm wander per axis, 0.3 deg, 15 ms),
   seeded with the clip's seed as ``app.evaluation.tracked_points.tracked_signals`` seeds it, so both
   models read the same noise draws; onto the 60 Hz grid by linear interpolation of
   positions and normalised linear interpolation of quaternions (the hub's), then every
   third frame (20 Hz);
3. frame by frame causal: frame t is the last frame of the MLP's 61-frame window ending at
   t (``AgrolMlp.pose_causal``), as a live system would answer;
4. the body put under the tracked headset (``place_under_headset``, the paper's step: the
   MLP predicts no translation). The papers' metrics are head-anchored, so this placement
   changes none of them; RE (root drift) is not a figure of this model (its root is the
   headset's), so it is left out of the comparison.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.vr_three_point import METRICS, difference_cells, run_set, store, table_lines  # noqa: E402

OURS = "3 points"
OURS_LABEL = "ours, 3 points"
MLP_LABEL = "AGRoL MLP, 3 points"
REACH = ", reach"  # the same answers, each arm then reaching its controller (inference/body/reach.py)
DIFF_METRICS = METRICS


def rig_points(motion, seed: int, noise=None):
    """The three devices' positions (T20, 3, 3) and orientations (T20, 3, 3, 3) at 20 Hz as
    the simulated rig reports them (module docstring, step 2); ``noise``: its
    ``TrackingNoise`` (default: the rig's own)."""
    import numpy as np

    from app.evaluation.tracked_points import RIG_RATE, _nlerp, rig_poses
    from inference.body.rotations import quat_to_matrix
    from inference.model.agrol_mlp import DEVICES
    from inference.signals.resample import STEP
    from sim_devices.devices.vr_rig import TrackingNoise

    _, grid, t_rig, poses = rig_poses(motion, DEVICES, seed, noise or TrackingNoise(), RIG_RATE)
    P = np.stack([np.stack([np.interp(grid, t_rig, np.stack(poses[p][0])[:, k]) for k in range(3)], -1)
                  for p in DEVICES], axis=1)
    Q = np.stack([_nlerp(np.stack(poses[p][1]), t_rig, grid) for p in DEVICES], axis=1)
    return P[::STEP], quat_to_matrix(Q[::STEP])


def run_mlp(held_out: str, agrol: Path, seed: int, cache: Path, reach: bool = False) -> list:
    """Per-clip metrics of the MLP on one held-out set (cached beside our model's); ``reach``:
    its arms then reach the controllers as ours do in the ", reach" rows."""
    key = cache / f"{held_out}__agrol_mlp{'_reach' if reach else ''}__{agrol.parent.name}_{agrol.stem}.pkl"
    if key.exists() and key.stat().st_mtime > agrol.stat().st_mtime:
        return pickle.loads(key.read_bytes())
    from app.evaluation.tracked_points import tracked_points_input
    from inference.body.reach import reach_hands
    from inference.evaluation.runner import clip_input, clip_seed, face_forward, load_motions
    from inference.metrics.errors import evaluate_clip
    from inference.model.agrol_mlp import DEVICES, input_features, load_agrol, place_under_headset
    from inference.signals.resample import FPS_MODEL
    from inference.training.splits import held_out_files

    model, _ = load_agrol(agrol)
    t0 = time.time()
    metrics = []
    for motion in load_motions(held_out_files(held_out)):
        aligned = face_forward(motion)
        seed_c = clip_seed(seed, motion.name)
        inp = clip_input(aligned, [], align=False, seed=seed_c,
                         reach=tracked_points_input(DEVICES) if reach else None)
        pos, rot = rig_points(aligned, seed_c)
        T = inp.rot.shape[0]
        if pos.shape[0] != T:
            raise ValueError(f"{motion.name}: rig gives {pos.shape[0]} frames at 20 Hz, the truth {T}")
        R = model.pose_causal(input_features(pos, rot))
        root, joints = place_under_headset(R, aligned.body.offsets, aligned.body.height, pos[:, 0])
        if inp.reach is not None:
            R, joints = reach_hands(R, root, aligned.body, *inp.reach)
        metrics.append(evaluate_clip(inp.name, R, root, joints, inp.rot, inp.root, inp.joints, FPS_MODEL))
    print(f"vr_baseline: {held_out} AGRoL MLP: {len(metrics)} clips in {time.time() - t0:.0f} s", file=sys.stderr)
    return store(key, metrics)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--agrol", type=Path, required=True, help="the MLP's file (python -m inference.training.agrol)")
    ap.add_argument("--sets", default="dg,cmu-val,sad", help="held-out sets (inference/training/splits.py)")
    ap.add_argument("--model", default="diffusion", help="our model, as vr_three_point.py takes it")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--markdown", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=None, help="default: runs/vr/cache (vr_three_point's)")
    args = ap.parse_args(argv)
    if not args.agrol.is_file():
        ap.error(f"--agrol {args.agrol}: no such file")

    import torch

    from inference.metrics.errors import paired_difference, summarize

    torch.set_num_threads(1)
    cache = args.cache or Path("runs/vr/cache")
    out: dict = {"model": args.model, "agrol": str(args.agrol), "seed": args.seed, "sets": {}}
    for held_out in [s.strip() for s in args.sets.split(",") if s.strip()]:
        per = {OURS_LABEL: run_set(held_out, OURS, args.model, args.seed, cache),
               MLP_LABEL: run_mlp(held_out, args.agrol, args.seed, cache),
               OURS_LABEL + REACH: run_set(held_out, OURS + REACH, args.model, args.seed, cache),
               MLP_LABEL + REACH: run_mlp(held_out, args.agrol, args.seed, cache, reach=True)}
        entry: dict = {"clips": len(per[OURS_LABEL]), "rows": {}, "differences": {}}
        for label, metrics in per.items():
            s = summarize(metrics)
            entry["rows"][label] = {m: s.get(m) for m in METRICS}
        for a, b in ((OURS_LABEL, MLP_LABEL), (OURS_LABEL + REACH, MLP_LABEL + REACH)):
            entry["differences"][f"{a} - {b}"] = {
                m: paired_difference(per[a], per[b], m, seed=args.seed).as_dict() for m in DIFF_METRICS}
        out["sets"][held_out] = entry
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
    if args.markdown:
        args.markdown.write_text(markdown(out))
    print(json.dumps(out))
    return 0


def markdown(out: dict) -> str:
    lines = []
    for held_out, e in out["sets"].items():
        lines += [f"**@{held_out}** ({e['clips']} clips)", "", *table_lines(e["rows"], "model"), ""]
        lines += [f"- {name}: {difference_cells(d)}" for name, d in e["differences"].items()]
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
