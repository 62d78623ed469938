"""Training of AGRoL's MLP baseline (``inference.model.agrol_mlp``) on the shipped diffusion
model's data.

    python -m inference.training.agrol --out runs/agrol_mlp --steps 4000

Data: the ``data`` entries of ``configs/shipped_diffusion.json`` (``splits.train_set`` with
the HDM05 speed copies and per-window energy draws; ``splits.val_set``: HDM05 actor dg),
through the same dataset cache, so the two models learn from the same windows. Each
drawn window is turned about the vertical by a random angle (as the diffusion model's
``augment_yaw``); the three devices come from its clean orientations by forward
kinematics with the clip's own bones (``inference.body.tracked``, the rig's placement),
with the rig's white tracking error (1 mm per axis, 0.3 deg per axis). The window is drawn
one frame longer than the model's, so its first frame's velocity and rotation change are
real ones, as they are in a live stream.

Optimiser as the paper's (sec. 4.1): Adam, learning rate 3e-4 dropping to 1e-5 (here for
the last 10 % of the steps, the paper's drop is after 200 k of its iterations), weight
decay 1e-4. Batch 32 (the paper's 256 does not fit the time on two shared CPU cores).

Output in ``--out``: ``checkpoint.pt`` every ``--ckpt-every`` steps (the run resumes from
it: model, optimiser, step and random states), ``log.jsonl`` (one JSON object per logged
step and per validation), and ``agrol_mlp.pt``, the model, when the steps are done.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from inference.body.rotations import matrix_angle_between, rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS
from inference.features.layout import SL_DP, SL_PZ, SL_ROT
from inference.metrics.errors import EVAL_SEGMENTS
from inference.model.agrol_mlp import (
    AgrolConfig,
    AgrolMlp,
    add_tracking_noise,
    agrol_loss,
    input_features,
    load_agrol,
    save_agrol,
    window_devices,
)
from inference.training.augment import rotate_yaw

SHIPPED_CONFIG = Path(__file__).resolve().parents[2] / "configs" / "shipped_diffusion.json"
JITTER_M = 0.001  # the simulated rig's white position error, per axis (TrackingNoise.jitter_m)
JITTER_DEG = 0.3  # and its orientation error, per axis (TrackingNoise.jitter_deg)


def window_batch(batch: dict[str, np.ndarray], gen: torch.Generator, yaw: bool = True,
                 jitter_m: float = JITTER_M, jitter_deg: float = JITTER_DEG) -> tuple[torch.Tensor, torch.Tensor,
                                                                                    torch.Tensor]:
    """(inputs (B, N, 54), true orientations (B, N, 24, 3, 3), offsets (B, 24, 3)) from a
    dataset batch of N + 1 frames (module docstring): the first frame only gives the
    second its velocity and rotation change."""
    x = torch.as_tensor(batch["x"], dtype=torch.float32)
    B, N1 = x.shape[:2]
    if yaw:
        x = rotate_yaw(x, (2 * torch.rand(B, generator=gen) - 1) * math.pi)
    R = rot6d_to_matrix(x[..., SL_ROT].reshape(B, N1, N_SEGMENTS, 6))
    xy = torch.cumsum(x[..., SL_DP], dim=1)
    root = torch.cat([xy - xy[:, -1:], x[..., SL_PZ]], dim=-1)
    offsets = torch.as_tensor(batch["offsets"], dtype=torch.float32)
    height = torch.as_tensor(batch["height"], dtype=torch.float32)
    pos, rot = window_devices(R, root, offsets, height)
    pos, rot = add_tracking_noise(pos, rot, jitter_m, jitter_deg, gen)
    return input_features(pos, rot)[:, 1:], R[:, 1:], offsets


def shipped_data() -> dict[str, Any]:
    """The shipped diffusion model's data entries (train, val)."""
    return json.loads(SHIPPED_CONFIG.read_text())["data"]


def load_data(synthetic: bool):
    from inference.training.data import load_dataset

    if synthetic:
        return (load_dataset({"synthetic": {"clips": 8, "frames": 120, "seed": 0}}),
                load_dataset({"synthetic": {"clips": 4, "frames": 120, "seed": 1}}))
    spec = shipped_data()
    return load_dataset(spec["train"]), load_dataset(spec["val"])


def validate(model: AgrolMlp, batches: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]) -> dict[str, float]:
    """Mean loss and the last frame's GA (deg, the evaluated segments) over fixed batches."""
    model.eval()
    losses, ga = [], []
    with torch.no_grad():
        for inp, R, off in batches:
            pred = model(inp)
            loss, _ = agrol_loss(pred, R, off)
            losses.append(float(loss))
            Rp = rot6d_to_matrix(pred[:, -1].reshape(-1, N_SEGMENTS, 6)).double()
            ang = matrix_angle_between(Rp, R[:, -1].double())[:, list(EVAL_SEGMENTS)]
            ga.append(float(torch.rad2deg(ang).mean()))
    model.train()
    return {"val_loss": float(np.mean(losses)), "val_ga_last_deg": float(np.mean(ga))}


def train(out: Path, steps: int, batch: int = 32, cfg: AgrolConfig = AgrolConfig(), lr: float = 3e-4,
          lr_final: float = 1e-5, drop_at: float = 0.9, weight_decay: float = 1e-4, ckpt_every: int = 250,
          val_every: int = 250, val_batches: int = 4, log_every: int = 25, seed: int = 0, synthetic: bool = False,
          data=None) -> AgrolMlp:
    """Train (or resume) to ``steps``; returns the model. ``data``: (train, val) datasets
    to use instead of loading them."""
    out.mkdir(parents=True, exist_ok=True)
    train_ds, val_ds = data if data is not None else load_data(synthetic)
    model = AgrolMlp(cfg)
    opt = torch.optim.Adam(model.parameters(), lr=lr, weight_decay=weight_decay)
    rng = np.random.default_rng(seed)
    gen = torch.Generator().manual_seed(seed)
    step = 0
    ckpt = out / "checkpoint.pt"
    if ckpt.exists():
        model, extra = load_agrol(ckpt)
        if model.cfg != cfg:
            raise ValueError(f"{ckpt}: model config {model.cfg} differs from the one asked for {cfg}")
        opt = torch.optim.Adam(model.parameters(), lr=lr, weight_decay=weight_decay)
        opt.load_state_dict(extra["optimizer"])
        rng.bit_generator.state = extra["numpy_rng"]
        gen.set_state(extra["torch_rng"])
        step = int(extra["step"])
        print(f"agrol: resuming {ckpt} at step {step}", file=sys.stderr)
    vrng = np.random.default_rng(10_000 + seed)
    vgen = torch.Generator().manual_seed(10_000 + seed)
    val = [window_batch(val_ds.sample(vrng, batch, cfg.window + 1), vgen) for _ in range(val_batches)] \
        if val_ds is not None and val_batches else []
    log = (out / "log.jsonl").open("a")

    def checkpoint() -> None:
        save_agrol(ckpt, model, optimizer=opt.state_dict(), numpy_rng=rng.bit_generator.state,
                   torch_rng=gen.get_state(), step=step)

    if step == 0:
        log.write(json.dumps({"step": 0, "parameters": model.n_parameters(), "config": cfg.__dict__,
                              "batch": batch, "steps": steps}) + "\n")
    model.train()
    t0, n0 = time.time(), step
    while step < steps:
        for g in opt.param_groups:
            g["lr"] = lr if step < drop_at * steps else lr_final
        inp, R, off = window_batch(train_ds.sample(rng, batch, cfg.window + 1), gen)
        loss, parts = agrol_loss(model(inp), R, off)
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        if step % log_every == 0 or step == steps:
            sec = (time.time() - t0) / max(step - n0, 1)
            log.write(json.dumps({"step": step, "loss": float(loss.detach()), **parts, "lr": opt.param_groups[0]["lr"],
                                  "sec_per_step": round(sec, 4)}) + "\n")
            log.flush()
        if val and (step % val_every == 0 or step == steps):
            log.write(json.dumps({"step": step, **validate(model, val)}) + "\n")
            log.flush()
        if step % ckpt_every == 0 or step == steps:
            checkpoint()
    save_agrol(out / "agrol_mlp.pt", model, step=step, data="configs/shipped_diffusion.json" if not synthetic
               else "synthetic")
    log.close()
    return model


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--steps", type=int, required=True)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--d-model", type=int, default=AgrolConfig.d_model)
    ap.add_argument("--blocks", type=int, default=AgrolConfig.blocks)
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--ckpt-every", type=int, default=250)
    ap.add_argument("--val-every", type=int, default=250)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--synthetic", action="store_true", help="synthetic clips (a smoke run of the machinery)")
    args = ap.parse_args(argv)
    if args.steps < 1 or args.batch < 1:
        ap.error("--steps and --batch must be positive")
    torch.set_num_threads(args.threads)
    model = train(args.out, args.steps, args.batch, AgrolConfig(d_model=args.d_model, blocks=args.blocks), args.lr,
                  ckpt_every=args.ckpt_every, val_every=args.val_every, seed=args.seed, synthetic=args.synthetic)
    print(json.dumps({"model": str(args.out / "agrol_mlp.pt"), "parameters": model.n_parameters()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
