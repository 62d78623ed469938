"""`imucap train`: train the DiffusionPoser denoiser or the regressive baseline.

    imucap train --config cfg.json --out runs/x [--resume | --init other/last.pt] [--steps N]
                 [--model diffusion|regressor] [--seed S]

Multi-process (one process per core or GPU):

    torchrun --standalone --nproc_per_node 2 -m app.cli.main train --config cfg.json --out runs/x

The config is a JSON object with the fields of ``inference.training.TrainConfig``; its
``data`` entry names the training and validation sets (see ``training.load_dataset``).
With ``--resume`` and no ``--config`` the run continues with the configuration stored in
its checkpoint. ``--export FILE`` trains nothing: it writes OUT/last.pt's EMA weights as an
inference model file (``--fp16`` to halve it, ``--default-steps`` for the live poser).
``--blend A B --blend-weight W --export FILE`` mixes two model files' weights, B a fine-tune
of A: ``imucap train --blend shipped.pt tuned.pt --blend-weight 0.35 --export mix.pt``.

``--contact-detector`` trains the shank contact detector instead (inference/poser/contact_detector.py)
on the issue's training split (or ``--data PATH...``), reports its accuracy on the held-out
sets (or ``--val PATH...``) and writes OUT/contact_detector.pt; copy that to
inference/weights/ to ship it. ``--pelvis-odometry`` does the same for the pelvis odometry
(inference/poser/pelvis_odometry.py; OUT/pelvis_odometry.pt, its forward and backward nets and
their gate; its held-out figures are the root errors RE2/5/10 of the path it integrates
alone from each clip's measured pelvis).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

# choices only (cheap modules; the heavy imports stay in run())
INPAINT_MODES = ("paper", "replace", "ddim", "replace-ddim")
HISTORY_MODES = ("reconstructed", "measured")
NOISE_MODES = ("fresh", "fixed", "mean")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("train", help="train the model (diffusion) or the regressive baseline",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=Path, help="training config JSON (TrainConfig fields)")
    p.add_argument("--out", type=Path, help="run directory: last.pt, model.pt, train.jsonl (required unless "
                                                  "--retag)")
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
    p.add_argument("--at-step", type=int, metavar="N",
                   help="with --export: the run's kept checkpoint of step N (OUT/step_000NNNN.pt, kept every "
                        "keep_every steps) instead of OUT/last.pt, e.g. to score a run while it goes on")
    p.add_argument("--retag", type=Path, metavar="MODEL_PT",
                   help="with --export: take MODEL_PT, a model file, instead of OUT/last.pt and only change the "
                        "poser defaults given (weights untouched), e.g. to ship --mirror with a baseline whose run "
                        "is gone")
    p.add_argument("--blend", type=Path, nargs=2, metavar=("MODEL_A", "MODEL_B"),
                   help="with --export: write a mix of two model files' weights, (1 - W) * A + W * B "
                        "(W: --blend-weight), with A's config and poser defaults; B must be a fine-tune of A "
                        "(imucap train --init), so both share the network and the feature normaliser")
    p.add_argument("--blend-weight", type=float, default=0.5, metavar="W",
                   help="with --blend: B's share of the weights (0..1, default 0.5)")
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
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="with --export: the poser averages each model answer with the answer for the mirror-image "
                        "window (inference.mirror; twice the batch per call)")
    p.add_argument("--mirror-chains", action=argparse.BooleanOptionalAction, default=None,
                   help="with --export (and --mirror): average whole chains, the model's and its mirror image's, "
                        "rather than each call's answers (the shipped file's setting)")
    p.add_argument("--draws-from", metavar="MODEL",
                   help="with --export: the model whose calls make the poser's confidence draws (a shipped name "
                        "such as diffusion, or a file reading the same features), for a chain student that never "
                        "learnt the re-noised states the draws start from")
    p.add_argument("--reading", metavar="NAME",
                   help="with --export: the dataset reading (none, bandai, hdm05, cmu) a model with reading tokens "
                        "answers in when not told, which is what the poser gets; none = the untold answer")
    p.add_argument("--contact-detector", action="store_true",
                   help="train the shank contact detector (writes OUT/contact_detector.pt)")
    p.add_argument("--pelvis-odometry", action="store_true",
                   help="train the pelvis odometry, the root's walk without shanks (writes OUT/pelvis_odometry.pt)")
    p.add_argument("--data", nargs="+", type=Path, metavar="PATH",
                   help="with --contact-detector / --pelvis-odometry: motion files/folders to train on "
                        "(default: the issue's split)")
    p.add_argument("--val", nargs="+", type=Path, metavar="PATH",
                   help="with --contact-detector / --pelvis-odometry: held-out motion files/folders "
                        "(default: dg and the sad walks)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from inference.training.config import LAST, TrainConfig
    from inference.training.loop import export_model, kept_checkpoint_name, train

    if args.retag is not None and args.export is None:
        raise ValueError("--retag needs --export DEST")
    if args.blend is not None and (args.export is None or args.retag is not None):
        raise ValueError("--blend needs --export DEST (and no --retag)")
    if args.out is None and args.retag is None and args.blend is None:
        raise ValueError("--out is required")
    if args.contact_detector and args.pelvis_odometry:
        raise ValueError("--contact-detector and --pelvis-odometry train different files: pick one")
    if args.contact_detector or args.pelvis_odometry:
        return run_helper_stage(args)
    if args.export is not None:
        if args.default_steps is not None:
            from inference.model.diffusion import parse_steps

            parse_steps(args.default_steps)  # reject a bad list now, not in the poser
        poser = {k: v for k, v in (("inpaint_mode", args.inpaint_mode), ("history", args.history),
                                   ("noise", args.noise), ("contact_threshold", args.contact_threshold),
                                   ("mirror", args.mirror), ("mirror_chains", args.mirror_chains),
                                   ("draws_from", args.draws_from))
                 if v is not None}
        if args.default_steps is not None and (args.blend is not None or args.retag is not None):
            poser["default_steps"] = args.default_steps  # a model file's defaults (export_model takes it apart)
        if args.blend is not None:
            from inference.model.files import blend_models

            blend_models(args.blend[0], args.blend[1], args.blend_weight, args.export, meta=poser)
            print(json.dumps({"exported": str(args.export), "blend": [str(p) for p in args.blend],
                              "weight": args.blend_weight, **poser}))
            return 0
        if args.retag is not None:
            from inference.model.files import retag_model

            retag_model(args.retag, args.export, poser, reading=args.reading)
            print(json.dumps({"exported": str(args.export), "retagged": str(args.retag), **poser}))
            return 0
        src = args.out / LAST if args.at_step is None else args.out / kept_checkpoint_name(args.at_step)
        if not src.exists():
            raise FileNotFoundError(f"--export: no checkpoint {src}"
                                    + ("" if args.at_step is None else " (kept every keep_every steps)"))
        export_model(src, args.export, fp16=args.fp16, default_steps=args.default_steps, poser=poser,
                     reading=args.reading)
        print(json.dumps({"exported": str(args.export), "fp16": args.fp16, "checkpoint": str(src)}))
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
    rc = 130 if res.stopped_early else 0
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        _leave_distributed_run(rc)
    return rc


def _leave_distributed_run(rc: int) -> None:
    """End a torchrun worker without interpreter teardown. DistributedDataParallel's reducer
    keeps the gloo process group alive after `destroy_process_group` (its worker threads
    are still running then: 4 OS threads before and after, 1 without DDP), so the group
    is torn down during interpreter finalization, where a gloo thread can abort the
    process ("terminate called without an active exception", SIGABRT; seen once in CI).
    Training has finished and its files are closed by now, so the worker flushes what it
    printed and exits at once with its own code."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


def run_helper_stage(args: argparse.Namespace) -> int:
    """Train one of the poser's small helper stages (contact detector, pelvis odometry) on
    every frame of the split's clips; both train in about a minute on one core."""
    from app.live.model_choice import set_torch_threads
    from inference.training import splits

    set_torch_threads(1)
    build = lambda paths: splits.build_files(paths, progress=not args.no_progress)  # noqa: E731
    train_clips = build(args.data).clips if args.data else splits.train_set(progress=not args.no_progress).clips
    val = ({"val": build(args.val).clips} if args.val else
           {"dg": splits.val_set(progress=False).clips, "sad": build(splits.root_val_files()).clips})
    if args.contact_detector:
        from inference.poser.contact_detector import DetectorTraining as Config
        from inference.poser.contact_detector import save_detector as save
        from inference.poser.contact_detector import train_detector as fit
        name, kept = "contact_detector", ("acc_",)
    else:
        from inference.poser.pelvis_odometry import OdometryTraining as Config
        from inference.poser.pelvis_odometry import save_odometry as save
        from inference.poser.pelvis_odometry import train_two_way as fit
        name, kept = "pelvis_odometry", tuple(f"{k}_" for k in val)
    cfg = Config(steps=args.steps or Config.steps, seed=args.seed or 0)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "train.jsonl", "a") as log:
        def report(entry: dict) -> None:
            log.write(json.dumps(entry) + "\n")
            log.flush()
            if not args.no_progress:
                print(json.dumps(entry), file=sys.stderr)

        stage = fit(train_clips, val, cfg, progress=report)
    final = cfg.log[-1]
    meta = {"steps": cfg.steps, "seed": cfg.seed, "train_frames": int(sum(len(c) for c in train_clips)),
            "data": [str(p) for p in args.data] if args.data else "inference.training.splits:train_set",
            **stage.meta, **{k: v for k, v in final.items() if k.startswith(kept)}}
    save(args.out / f"{name}.pt", stage, meta)
    print(json.dumps({name: str(args.out / f"{name}.pt"), **meta}))
    return 0


def _is_main() -> bool:
    return int(os.environ.get("RANK", "0")) == 0
