"""The window's answer k frames back, against the newest frame's, per model and sensor set.

    .venv/bin/python benchmarks/lagged_answer.py --models diffusion runs/X/export.pt \
        [--data @dg @cmu-val] [--limit 20] [--sets "6 sites" pelvis+shanks] [--lags 6] [--json out.json]

Why this exists: a live pose must be the newest frame's, which has only the sensors' past; an
import, a replay or a report can wait and show each frame once k more frames have come in
(docs/real_signals.md, "The thighs stage by stage": on the real logs the inferred thighs
trail their sensors by 150-200 ms). Whether that pays depends on how good the model's answer
k frames back is, which depends on what its training weighed (``TrainConfig.answer_lag``).

Scored on synthesized held-out clips as ``imucap evaluate`` synthesizes them (same noise,
seeds, facing), frame by frame through the live ``Poser`` with its output stage off (no
smoothing: the window's rows are the model's answers), GA over the evaluated segments for
each k: step t's window row ``N-1-k`` against the truth at ``t-k``. Per model, set and k:
the mean over clips of the per-clip GA, and per clip (``per_clip``) for paired intervals.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

SETS = {
    "6 sites": "pelvis,head,l_wrist,r_wrist,l_shank,r_shank",
    "pelvis+shanks": "pelvis,l_shank,r_shank",
    "shanks": "l_shank,r_shank",
    "3 sites": "pelvis,l_wrist,r_wrist",
}


def lagged_ga(model, inp, seed: int, lags: int) -> np.ndarray:
    """(lags + 1,) GA of the window's answer k = 0..lags frames back over one clip."""
    from inference.body.rotations import rot6d_to_matrix
    from inference.evaluation.runner import clip_poser
    from inference.features.layout import SL_ROT
    from inference.metrics.errors import global_angle_error
    from inference.poser.poser import reconstruct_offline

    poser = clip_poser(model, inp, seed=seed, smoothing=False)
    K = lags + 1
    rows: list[np.ndarray] = []
    predict = poser._predict
    mean, std = poser._mean.numpy(), poser._std.numpy()

    def keep(win, mask):
        o = predict(win, mask)
        y = o[0, -K:].numpy() * std + mean
        rows.append(y[:, SL_ROT].reshape(K, -1, 6))
        return o

    poser._predict = keep
    reconstruct_offline(poser, inp.features, inp.mask)
    w = np.array(rows)  # (T, K, 24, 6): row K-1 is the newest frame
    out = np.full(K, np.nan)
    for k in range(K):
        est = rot6d_to_matrix(w[k:, K - 1 - k])  # step t's answer for frame t - k
        truth = inp.rot[: len(w) - k]
        out[k] = float(global_angle_error(est, truth).mean())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=["diffusion"])
    ap.add_argument("--data", nargs="+", default=["@dg"])
    ap.add_argument("--limit", type=int, default=None, help="the first N clips of each set (sorted)")
    ap.add_argument("--sets", nargs="+", default=["6 sites", "pelvis+shanks"], choices=list(SETS))
    ap.add_argument("--lags", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    from inference.evaluation.runner import clip_input, clip_seed, evaluation_noise, load_motions, resolve_models
    from inference.training.splits import held_out_files

    models = resolve_models(a.models)
    result: dict = {}
    for data in a.data:
        files = held_out_files(data) if data.startswith("@") else [Path(data)]
        motions = load_motions(files, a.limit)
        for set_name in a.sets:
            sites = SETS[set_name].split(",")
            inputs = [(m.name, clip_input(m, sites, noise=evaluation_noise(), seed=clip_seed(a.seed, m.name)))
                      for m in motions]
            for spec, model in models.items():
                per_clip = {}
                for name, inp in inputs:
                    per_clip[name] = lagged_ga(model, inp, clip_seed(a.seed, name), a.lags)
                ga = np.array(list(per_clip.values()))
                entry = {"mean_ga_deg": np.round(ga.mean(0), 3).tolist(),
                         "per_clip": {n: np.round(v, 3).tolist() for n, v in per_clip.items()}}
                result.setdefault(data, {}).setdefault(set_name, {})[spec] = entry
                print(json.dumps({"data": data, "set": set_name, "model": spec, "mean_ga_deg": entry["mean_ga_deg"]}),
                      flush=True)
    if a.json is not None:
        a.json.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
