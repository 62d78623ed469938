"""`imucap train`: train the DiffusionPoser denoiser or the regressive baseline.

    imucap train --config cfg.json --out runs/x [--resume | --init other/last.pt] [--steps N]
                 [--model diffusion|regressor] [--seed S]

Multi-process (one process per core or GPU):

    torchrun --standalone --nproc_per_node 2 -m app.cli train --config cfg.json --out runs/x

The config is a JSON object with the fields of ``inference.training.TrainConfig``; its
``data`` entry names the training and validation sets (see ``training.load_dataset``).
With ``--resume`` and no ``--config`` the run continues with the configuration stored in
its checkpoint. ``--export FILE`` trains nothing: it writes OUT/last.pt's EMA weights as an
inference model file (``--fp16`` to halve it, ``--default-steps`` for the live poser).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# choices only (cheap modules; the heavy imports stay in run())
INPAINT_MODES = ("paper", "replace", "ddim", "replace-ddim")
HISTORY_MODES = ("reconstructed", "measured")
NOISE_MODES = ("fresh", "fixed")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("train", help="train the model (diffusion) or the regressive baseline",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=Path, help="training config JSON (TrainConfig fields)")
    p.add_argument("--out", type=Path, required=True, help="run directory: last.pt, model.pt, train.jsonl")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    p.add_argument("--init", type=Path, metavar="LAST_PT",
                   help="start from another run's last.pt (weights, EMA, normaliser; fresh optimiser): fine-tuning")
    p.add_argument("--steps", type=int, help="total optimiser steps (overrides the config)")
    p.add_argument("--stop-after", type=int, metavar="N",
                   help="end this run at total step N with a checkpoint, as an interruption would (the LR "
                        "schedule keeps its --steps horizon)")
    p.add_argument("--model", choices=("diffusion", "regressor"), help="model kind (overrides the config)")
    p.add_argument("--seed", type=int, help="random seed (overrides the config)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--export", type=Path, metavar="FILE", help="write OUT/last.pt's EMA weights to FILE and exit")
    p.add_argument("--fp16", action="store_true", help="with --export: store half-precision weights")
    p.add_argument("--default-steps", help="with --export: step list the poser uses (e.g. 10, paper, 1000,500,0)")
    p.add_argument("--inpaint-mode", choices=INPAINT_MODES,
                   help="with --export: how the poser inpaints with this model (default: as trained)")
    p.add_argument("--history", choices=HISTORY_MODES,
                   help="with --export: what of the history the poser tells the model is known")
    p.add_argument("--noise", choices=NOISE_MODES, help="with --export: inpainting noise per frame")
    p.add_argument("--contact-threshold", type=float,
                   help="with --export: predicted contact value above which the root correction counts a foot "
                        "point as planted (default 0.5)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from inference.training import LAST, TrainConfig, export_model, train

    if args.export is not None:
        if args.default_steps is not None:
            from inference.diffusion import parse_steps

            parse_steps(args.default_steps)  # reject a bad list now, not in the poser
        poser = {k: v for k, v in (("inpaint_mode", args.inpaint_mode), ("history", args.history),
                                   ("noise", args.noise), ("contact_threshold", args.contact_threshold))
                 if v is not None}
        export_model(args.out / LAST, args.export, fp16=args.fp16, default_steps=args.default_steps, poser=poser)
        print(json.dumps({"exported": str(args.export), "fp16": args.fp16}))
        return 0
    if args.config is not None:
        cfg = TrainConfig.load(args.config)
    elif args.resume:
        ckpt = torch.load(args.out / LAST, map_location="cpu", weights_only=False)
        cfg = TrainConfig.from_dict(ckpt["train_config"])
    else:
        raise ValueError("--config is required (unless resuming)")
    if args.steps is not None:
        cfg.steps = args.steps
    if args.model is not None:
        cfg.kind = args.model
    if args.seed is not None:
        cfg.seed = args.seed
    if args.init is not None and args.resume:
        raise ValueError("--init starts a new run; --resume continues one: pass only one")
    res = train(cfg, args.out, resume=args.resume, progress=not args.no_progress, init_from=args.init,
                stop_after=args.stop_after)
    if res.checkpoint is not None and _is_main():
        summary = {"step": res.step, "loss": res.last_loss, "checkpoint": str(res.checkpoint),
                   "stopped_early": res.stopped_early}
        if res.val:
            summary.update(res.val)
        print(json.dumps(summary), file=sys.stdout)
    return 130 if res.stopped_early else 0


def _is_main() -> bool:
    import os

    return int(os.environ.get("RANK", "0")) == 0
