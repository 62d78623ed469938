"""Training of the denoiser (and of the regressive baseline) for `imucap train`.

One trainer for both model kinds, so the baseline gets exactly the same data, sampling,
augmentation, losses, optimiser and schedule:

- diffusion: draw t ~ U{0..T} (paper 3.2.3), noise the normalised window, predict x0.
- regressor: draw a random observation mask, feed observed features + mask, predict x0.

Losses (paper eq. 5-10), computed on the prediction mapped back to physical units:
simple (MSE of all normalised features incl. contacts), velocity of the 6D orientations,
FK joint positions relative to the root, drift (cumulative dp path) and foot slide
(predicted contact x foot-point velocity including the root motion). Each term is put in
units where a "moderate" error is O(0.1-1) (see ``LossWeights``) and logged unweighted,
so the weights can be tuned from the log.

Robustness: the random state of every step is derived from (seed, rank, step), so a run
resumed from a checkpoint draws exactly the batches, noise and dropout an uninterrupted
run would have drawn; checkpoints are written atomically (temp file + os.replace);
SIGINT/SIGTERM stop at the next step boundary with a checkpoint. Multi-process runs use
torchrun + DistributedDataParallel (gloo on CPU, nccl on GPU).

Data interface (``FeatureDataset`` in inference/training/dataset.py, or ``ArrayDataset`` here):
``clips`` list of (T_i, 190) float32 unnormalised features, ``heights`` (n,), ``offsets``
(n, 24, 3), ``weights`` (n,), ``sample(rng, batch, window) -> {x, height, offsets}``.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from inference.body.rotations import matrix_angle_between, rot6d_to_matrix
from inference.body.skeleton import CONTACTS, METRIC_EXCLUDED, N_SEGMENTS, SEGMENT_INDEX, SEGMENTS
from inference.features.layout import (
    SL_ROT,
    observation_mask,
)
from inference.features.mirror import MirrorAveraged, mirror_features, mirror_points
from inference.model.config import ModelConfig, atomic_torch_save
from inference.model.denoiser import deepened_state_dict
from inference.model.diffusion import Schedule, ddim_step, inpaint, paper_steps, parse_steps, symmetric_start
from inference.model.files import MODEL_FORMAT, build_model, newest_positions, save_model, with_reading
from inference.model.regressor import random_observation_mask
from inference.training.augment import rotate_yaw, scale_features, sensor_effects
from inference.training.config import CHECKPOINT_FORMAT, LAST, LOG_FILE, MODEL_FILE, VAL_SITES, TrainConfig
from inference.training.data import Dataset, default_data, load_dataset, window_stats
from inference.training.distributed import all_reduce_mean, any_rank, barrier, init_distributed
from inference.training.losses import (
    contact_offsets_for,
    inpaint_mode_for,
    motion_losses,
    sites_known_share,
    total_loss,
)
from inference.training.points import draw_presence, known_orientations, window_points

_EVAL_SEGMENTS = [i for i in range(N_SEGMENTS) if i not in {SEGMENT_INDEX[s] for s in METRIC_EXCLUDED}]


# --------------------------------------------------------------------------- configuration


# --------------------------------------------------------------------------- data


# --------------------------------------------------------------------------- augmentation


# --------------------------------------------------------------------------- losses


# --------------------------------------------------------------------------- EMA

class EMA:
    """Exponential moving average of a model's parameters (buffers copied).

    The averaged weights are what we ship and validate: diffusion models sampled with EMA
    weights are markedly smoother. Decay warms up as min(decay, (1+n)/(10+n)) so early
    averages are not dominated by the random initialisation.
    """

    def __init__(self, model: nn.Module, decay: float = 0.999) -> None:
        self.decay = decay
        self.model = copy.deepcopy(model).eval()
        for p in self.model.parameters():
            p.requires_grad_(False)

    @torch.no_grad()
    def update(self, model: nn.Module, step: int) -> None:
        d = min(self.decay, (1 + step) / (10 + step))
        ema_p = list(self.model.parameters())
        src_p = [p.detach() for p in model.parameters()]
        torch._foreach_mul_(ema_p, d)
        torch._foreach_add_(ema_p, src_p, alpha=1 - d)
        for b_ema, b in zip(self.model.buffers(), model.buffers()):
            b_ema.copy_(b)

    def state_dict(self) -> dict:
        return self.model.state_dict()

    def load_state_dict(self, sd: dict) -> None:
        self.model.load_state_dict(sd)


# --------------------------------------------------------------------------- one step

@dataclass
class StepContext:
    """What a training/validation step needs besides the model and the batch."""

    cfg: TrainConfig
    mean: Tensor
    std: Tensor
    schedule: Schedule
    teacher: nn.Module | None = None  # the distillation's teacher network (``TrainConfig.teacher``)

    @functools.cached_property
    def start_at(self) -> Tensor:
        """(F,) where the mean start's draw sits, normalised: 0 (the data mean), or its symmetric
        midpoint with ``TrainConfig.symmetric_start``."""
        if not self.cfg.symmetric_start:
            return torch.zeros(self.mean.shape[-1])
        return torch.as_tensor(symmetric_start(self.mean.numpy(), self.std.numpy()), dtype=torch.float32)

    @functools.cached_property
    def teacher_mirror(self) -> MirrorAveraged:
        """The teacher's mirror image operator (``TrainConfig.teacher_mirror_chains``), built once."""
        return MirrorAveraged(self.teacher, self.mean, self.std)


def kept_checkpoint_name(step: int) -> str:
    """The file name of the checkpoint a run keeps at ``step`` (``TrainConfig.keep_every``)."""
    return f"step_{step:07d}.pt"


def step_seeds(seed: int, rank: int, step: int) -> tuple[np.random.Generator, torch.Generator]:
    """The random state of one step, a pure function of (seed, rank, step): resuming a
    run anywhere reproduces the draws of an uninterrupted run."""
    ss = np.random.SeedSequence([seed, rank, step])
    rng = np.random.default_rng(ss)
    tseed = int(ss.generate_state(1, dtype=np.uint64)[0] & 0x7FFF_FFFF_FFFF_FFFF)
    gen = torch.Generator().manual_seed(tseed)
    torch.manual_seed(tseed ^ 0x5DEECE66D)  # dropout
    return rng, gen


def training_levels(cfg: TrainConfig, batch: int, gen: torch.Generator, T: int) -> Tensor:
    """Diffusion levels of one batch: uniform in 0..T (or biased by ``t_power``), with a
    share ``t_focus`` replaced by levels of the live step list."""
    if cfg.t_power == 1.0:
        t = torch.randint(0, T + 1, (batch,), generator=gen)
    else:
        u = torch.rand(batch, generator=gen) ** (1.0 / cfg.t_power)
        t = (u * (T + 1)).long().clamp(max=T)
    if cfg.t_focus > 0:
        levels = torch.as_tensor(parse_steps(cfg.infer_steps or "paper"), dtype=torch.long)
        pick = levels[torch.randint(0, len(levels), (batch,), generator=gen)]
        t = torch.where(torch.rand(batch, generator=gen) < cfg.t_focus, pick, t)
    return t


def param_groups(model: nn.Module, cfg: TrainConfig) -> list[dict]:
    """The optimiser's parameter groups: the reading tokens and the points' input layer on
    their own learning-rate scales (``reading_lr_scale``, ``points_lr_scale``) when they have
    one, everything else on the schedule; with ``train_only``, only the parameters named so
    (the rest frozen). Both start at zero in a fine-tune and would
    otherwise stay small for thousands of steps at a fine-tune's rate."""
    if cfg.train_only:
        trained = [n for n, _ in model.named_parameters() if n.startswith(tuple(cfg.train_only))]
        if not trained:
            raise ValueError(f"train_only {list(cfg.train_only)}: no parameter of this model starts so")
        for n, p in model.named_parameters():
            p.requires_grad_(n in trained)
    own: list[tuple[nn.Module, float]] = []
    for name, scale in (("reading_emb", cfg.reading_lr_scale), ("points_proj", cfg.points_lr_scale)):
        part = getattr(model, name, None)
        if part is not None and scale != 1.0:
            own.append((part, scale))
    live = [p for p in model.parameters() if p.requires_grad]
    if not own:
        return [{"params": live}]
    ids = {id(p) for part, _ in own for p in part.parameters()}
    return [{"params": [p for p in live if id(p) not in ids]},
            *({"params": [p for p in part.parameters() if p.requires_grad], "lr_scale": scale}
              for part, scale in own)]


def clip_readings(ds: Dataset | None, cfg: TrainConfig) -> np.ndarray | None:
    """Each clip's reading token (its dataset), for models that take one and datasets whose
    clips are named by their files; None otherwise."""
    names = getattr(ds, "names", None)
    if not (cfg.model.readings and names):
        return None
    from inference.training.splits import readings_of

    return readings_of(names)


def with_readings(batch: dict, readings: np.ndarray | None) -> dict:
    """The batch with each window's reading token, from ``clip_readings``."""
    if readings is not None and "clip" in batch:
        batch["reading"] = readings[np.asarray(batch["clip"])]
    return batch


def batch_loss(model: nn.Module, batch: dict, ctx: StepContext, rng: np.random.Generator,
               gen: torch.Generator) -> tuple[Tensor, dict[str, float]]:
    """Loss of one batch for either model kind; returns (weighted total, unweighted terms)."""
    cfg = ctx.cfg
    x = torch.as_tensor(batch["x"], dtype=torch.float32)
    B = x.shape[0]
    height = torch.as_tensor(batch["height"], dtype=torch.float32)
    offsets = torch.as_tensor(batch["offsets"], dtype=torch.float32)
    contact_np = batch.get("contact_offsets")
    if contact_np is None:
        contact_np = contact_offsets_for(np.asarray(batch["offsets"]), np.asarray(batch["height"]))
    contact_local = torch.as_tensor(contact_np, dtype=torch.float32)
    if cfg.augment_scale > 0:
        span = math.log1p(cfg.augment_scale)
        scale = torch.exp((2 * torch.rand(B, generator=gen) - 1) * span)
        x = scale_features(x, scale)
        height = height * scale
        offsets = offsets * scale[:, None, None]
        contact_local = contact_local * scale[:, None, None]
    if cfg.augment_yaw:
        x = rotate_yaw(x, torch.rand(B, generator=gen) * (2 * math.pi))
    if cfg.augment_mirror > 0:
        flip = torch.rand(B, generator=gen) < cfg.augment_mirror
        x = torch.where(flip[:, None, None], mirror_features(x), x)
        offsets = torch.where(flip[:, None, None], mirror_points(offsets, SEGMENTS), offsets)
        contact_local = torch.where(flip[:, None, None], mirror_points(contact_local, CONTACTS), contact_local)
    xn = (x - ctx.mean) / ctx.std
    # what the model is told of the measured entries: real sensors' errors on them when
    # configured (``SensorEffects``); the targets stay ``xn``
    xm = (sensor_effects(x, cfg.sensor_effects, gen) - ctx.mean) / ctx.std if cfg.sensor_effects.active else xn
    if cfg.mirror_average:
        model = MirrorAveraged(model, ctx.mean, ctx.std)
    told = ()  # the reading token, for models that take one
    if cfg.model.readings and "reading" in batch:
        reading = torch.as_tensor(batch["reading"], dtype=torch.long)
        if cfg.reading_drop > 0:
            reading = torch.where(torch.rand(B, generator=gen) < cfg.reading_drop, torch.zeros((), dtype=torch.long),
                                  reading)
        told = (reading,)
    unmasked = (None, *told) if told else ()  # the mask argument a mask-blind model is given
    m = None  # known entries, where the model is told them
    extra_terms: dict[str, Tensor] = {}  # loss terms beyond the motion's (a chain student's mirror term)
    if cfg.kind == "diffusion" and ctx.teacher is not None:
        distil = _chain_distilled if cfg.student_steps else _distilled
        pred, xn, m, extra_terms = distil(model, ctx, x, xn, xm, height, rng, told)
        if pred.shape[0] != B:  # one window per level of the student's chain
            reps = pred.shape[0] // B
            offsets, contact_local = offsets.repeat(reps, 1, 1), contact_local.repeat(reps, 1, 1)
    elif cfg.kind == "diffusion":
        t = training_levels(cfg, B, gen, ctx.schedule.T)
        noise = torch.randn(xn.shape, generator=gen)
        if cfg.mean_start > 0:
            top = (t == ctx.schedule.T) & (torch.rand(B, generator=gen) < cfg.mean_start)
            noise = torch.where(top[:, None, None], ctx.start_at, noise)
        z = ctx.schedule.q_sample(xn, t, noise=noise)
        if cfg.cond_prob > 0:
            # conditioning by replacement: known entries clean in z (and exact in the
            # output), so the loss is spent on what inpainting has to infer
            m = torch.as_tensor(random_observation_mask(rng, B, x.shape[1], cfg.mask))
            cond = torch.as_tensor(rng.random(B) < cfg.cond_prob)
            m &= cond[:, None, None]
            extra = {}
            if cfg.model.points:
                # tracked points (inference/training/points.py): their positions as the
                # model's position input, their orientations as known segment entries
                present = draw_presence(B, cfg.points_share, cfg.points_pelvis, gen) & cond[:, None]
                m = m | known_orientations(present, x.shape[1])
                extra["points"] = window_points(x, offsets, height, present, gen)
            z = torch.where(m, xm, z)
            out = (model(z, t, height, m, *told, **extra) if cfg.model.mask_input
                   else model(z, t, height, *unmasked))
            pred = torch.where(m, xn, out)
        else:
            pred = model(z, t, height, *unmasked)
    else:
        m = torch.as_tensor(random_observation_mask(rng, B, x.shape[1], cfg.mask))
        pred = model(torch.where(m, xm, torch.zeros(())), m, height)
    gate = sites_known_share(m, cfg.swing_gate) if cfg.swing_gate and m is not None else None
    terms = motion_losses(pred, xn, ctx.mean, ctx.std, offsets, contact_local, gate, cfg.answer_lag)
    terms.update(extra_terms)
    loss = total_loss(terms, cfg.loss)
    return loss, {k: float(v.detach()) for k, v in terms.items()}


def _distilled(model: nn.Module, ctx: StepContext, x: Tensor, xn: Tensor, xm: Tensor, height: Tensor,
               rng: np.random.Generator, told: tuple) -> tuple[Tensor, Tensor, Tensor, dict[str, Tensor]]:
    """One distillation batch: (the student's answer, its target, the known entries), each
    over the student's window (the newest ``cfg.model.window`` frames). The target is the
    teacher's chain on the whole window where unknown (mixed with the truth by
    ``teacher_share``) and the truth where known, as the student's answer is."""
    cfg = ctx.cfg
    if cfg.model.points or told:
        raise ValueError("distillation is for models without a position input or reading tokens")
    B, N = x.shape[:2]
    m = torch.as_tensor(random_observation_mask(rng, B, N, cfg.mask))
    start = torch.where(m, xm, torch.zeros(()))
    with torch.no_grad():
        if cfg.teacher_mirror_chains:
            op = ctx.teacher_mirror
            both = inpaint(ctx.teacher, torch.cat([start, op.mirror(start)]), torch.cat([m, m[..., op.idx]]),
                           torch.cat([height, height]), parse_steps(cfg.teacher_steps), schedule=ctx.schedule,
                           mode="replace-ddim", mask_input=True, start="mean")
            answer = 0.5 * (both[:B] + op.mirror(both[B:]))
        else:
            answer = inpaint(ctx.teacher, start, m, height, parse_steps(cfg.teacher_steps), schedule=ctx.schedule,
                             mode="replace-ddim", mask_input=True, start="mean")
    if cfg.teacher_share != 1.0:
        answer = cfg.teacher_share * answer + (1.0 - cfg.teacher_share) * xn
    target = torch.where(m, xn, answer)
    keep = slice(N - cfg.model.window, N)
    t = torch.full((B,), ctx.schedule.T, dtype=torch.long)
    out = model(start[:, keep], t, height, m[:, keep])
    return torch.where(m[:, keep], xn[:, keep], out), target[:, keep], m[:, keep], {}


def _chain_distilled(model: nn.Module, ctx: StepContext, x: Tensor, xn: Tensor, xm: Tensor, height: Tensor,
                     rng: np.random.Generator, told: tuple) -> tuple[Tensor, Tensor, Tensor, dict[str, Tensor]]:
    """One batch of chain distillation (``TrainConfig.student_steps``): the student runs its
    own chain (mean start, known entries replaced, deterministic DDIM), and each state it
    reaches is answered by the teacher's call at that state; the student's answers at all
    of them, stacked level by level (K*B windows), against the teacher's, the truth where
    known. Trained on its own states rather than the teacher's, a student's small errors
    at one level are what its next call learns to take back (as it must live).

    A student reading fewer frames than the teacher (``model.window < window``: the newest
    of them, as ``with_window`` gives it live) has no state for the older frames the teacher
    reads; there the teacher's own chain runs in step with the student's, so each teacher
    call sees the student's state in the newest frames and its own before them, as it would
    have live. Its answers then come a level at a time (the same arithmetic as one call)."""
    cfg = ctx.cfg
    if cfg.model.points or told:
        raise ValueError("distillation is for models without a position input or reading tokens")
    if cfg.model.window > cfg.window:
        raise ValueError(f"a chain student reads at most the teacher's {cfg.window} frames "
                         f"(model.window {cfg.model.window})")
    B, N = x.shape[:2]
    W = cfg.model.window
    keep = slice(N - W, N)
    sch = ctx.schedule
    levels = parse_steps(cfg.student_steps, sch.T)
    m = torch.as_tensor(random_observation_mask(rng, B, N, cfg.mask))
    mw, xw = m[:, keep], xm[:, keep]
    teacher = ctx.teacher_mirror if cfg.teacher_mirror_chains else ctx.teacher
    # the mean start: ~0 at the top level (or the symmetric midpoint), as ``inpaint`` starts live
    z = torch.where(m, xm, sch.sqrt_1mab(levels[0]) * ctx.start_at)
    states, answers = [], []
    with torch.no_grad():
        for i, t in enumerate(levels):
            tt = torch.full((B,), t, dtype=torch.long)
            states.append(z[:, keep])
            if W < N:
                answers.append(teacher(z, tt, height, m))
            if i + 1 == len(levels):
                break
            x0 = torch.where(mw, xw, model(z[:, keep], tt, height, mw))
            if W < N:
                x0 = torch.cat([torch.where(m, xm, answers[-1])[:, : N - W], x0], dim=1)
            z = torch.where(m, xm, ddim_step(sch, z, x0, t, levels[i + 1]))
        K = len(levels)
        zs = torch.cat(states)
        ts = torch.cat([torch.full((B,), t, dtype=torch.long) for t in levels])
        hs, mk, xk = height.repeat(K), mw.repeat(K, 1, 1), xn[:, keep].repeat(K, 1, 1)
        answer = torch.cat(answers)[:, keep] if W < N else teacher(zs, ts, hs, mk)
        if cfg.teacher_share != 1.0:
            answer = cfg.teacher_share * answer + (1.0 - cfg.teacher_share) * xk
        target = torch.where(mk, xk, answer)
    out = model(zs, ts, hs, mk)
    extra: dict[str, Tensor] = {}
    if cfg.loss.mirror > 0:
        # the student's answer to each state's mirror image, mirrored back, against its own answer
        op = ctx.teacher_mirror
        back = op.mirror(model(op.mirror(zs), ts, hs, mk[..., op.idx]))
        extra["mirror"] = (out - back).square().mul(~mk).sum() / (~mk).sum().clamp(min=1)
    return torch.where(mk, xk, out), target, mk, extra


def teacher_normaliser(cfg: TrainConfig) -> tuple[np.ndarray, np.ndarray]:
    """The feature normaliser of ``cfg.teacher``, for a student that starts from fresh weights
    (one of another size than the teacher, which ``--init`` cannot start)."""
    obj = torch.load(cfg.teacher, map_location="cpu", weights_only=False)
    return np.asarray(obj["norm_mean"]), np.asarray(obj["norm_std"])


def load_teacher(cfg: TrainConfig, mean: np.ndarray, std: np.ndarray) -> nn.Module | None:
    """The distillation's teacher network, checked to read the student's features."""
    if cfg.teacher is None:
        return None
    from inference.model.files import load_model

    if cfg.kind != "diffusion":
        raise ValueError("a teacher distils a diffusion model's chain; this run trains a regressor")
    if not 0.0 <= cfg.teacher_share <= 1.0:
        raise ValueError(f"teacher_share {cfg.teacher_share}: the teacher's weight in the target, from 0 to 1")
    teacher = load_model(cfg.teacher, window=None)
    if teacher.kind != "diffusion" or not teacher.config.mask_input:
        raise ValueError(f"teacher {cfg.teacher}: not a diffusion model that reads the mask")
    if teacher.config.window != cfg.window or cfg.model.window > cfg.window:
        raise ValueError(f"teacher {cfg.teacher} reads {teacher.config.window} frames: train on windows of that many "
                         f"(window) with a student of at most as many (model.window {cfg.model.window})")
    if not (np.allclose(teacher.norm_mean, mean) and np.allclose(teacher.norm_std, std)):
        raise ValueError(f"teacher {cfg.teacher}: its feature normaliser is not the student's (start the student "
                         "from the teacher's file with --init)")
    for p in teacher.model.parameters():
        p.requires_grad_(False)
    return teacher.model.eval()


@torch.no_grad()
def validate(model: nn.Module, val_set: Dataset, ctx: StepContext) -> dict[str, float]:
    """Validation on fixed batches (same windows, noise levels and masks every time, so
    numbers are comparable across the run): the training loss, and the live-setting
    orientation error: history known, last frame observed at the paper's 6 sites,
    reconstructed by inpainting with the 10D steps (diffusion) or one pass (regressor);
    mean geodesic angle of the last frame's evaluated segments, degrees."""
    cfg = ctx.cfg
    model.eval()
    sums: dict[str, float] = {}
    ga = []
    obs = torch.as_tensor(observation_mask(list(VAL_SITES)))
    readings = clip_readings(val_set, cfg)
    for i in range(cfg.val_batches):
        rng, gen = step_seeds(cfg.seed + 1_000_003, 0, i)
        batch = with_readings(val_set.sample(rng, cfg.val_batch, cfg.window), readings)
        _, terms = batch_loss(model, batch, ctx, rng, gen)
        for k, v in terms.items():
            sums[k] = sums.get(k, 0.0) + v
        sums["loss"] = sums.get("loss", 0.0) + sum(getattr(cfg.loss, k) * v for k, v in terms.items())
        x = torch.as_tensor(batch["x"], dtype=torch.float32)[:, -cfg.model.window:]
        xn = (x - ctx.mean) / ctx.std
        h = torch.as_tensor(batch["height"], dtype=torch.float32)
        mask = torch.ones_like(xn, dtype=torch.bool)
        mask[:, -1] = obs
        x_in = xn.clone()
        x_in[:, -1] = torch.where(obs, xn[:, -1], xn[:, -2])
        if cfg.kind == "diffusion":
            steps = parse_steps(cfg.infer_steps or "paper") if ctx.teacher is not None else paper_steps()
            out = inpaint(model, x_in, mask, h, steps, generator=gen, schedule=ctx.schedule,
                          mode=inpaint_mode_for(cfg), start="mean" if cfg.mean_start > 0 else "sample",
                          start_at=ctx.start_at if cfg.symmetric_start else None)
        else:
            out = torch.where(mask, x_in, model(x_in, mask, h))
        pred = out[:, -1] * ctx.std + ctx.mean
        Rp = rot6d_to_matrix(pred[:, SL_ROT].reshape(-1, N_SEGMENTS, 6))
        Rt = rot6d_to_matrix(x[:, -1, SL_ROT].reshape(-1, N_SEGMENTS, 6))
        ga.append(torch.rad2deg(matrix_angle_between(Rp, Rt))[:, _EVAL_SEGMENTS].mean().item())
    out_d = {f"val_{k}": v / cfg.val_batches for k, v in sums.items()}
    out_d["val_ga6_deg"] = float(np.mean(ga))
    return out_d


# --------------------------------------------------------------------------- distributed


# --------------------------------------------------------------------------- the trainer

def init_from_model_file(obj: dict, window: int | None = None) -> dict:
    """A model file (shipped weights: the EMA weights, fp16, and the normaliser) as the
    starting point of a fine-tune, in the shape ``--init`` takes from a checkpoint. The
    optimiser starts afresh; the normaliser stays the model's, as its weights expect it.
    ``window``: a diffusion student of fewer frames starts with the newest frames' learned
    positions (``files.with_window``)."""
    sd = {k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()}
    mc = dict(obj["model_config"])
    if window is not None and obj["kind"] == "diffusion" and "pos" in sd and window < mc.get("window", window):
        sd["pos"] = newest_positions(sd["pos"], window)
        mc["window"] = window
    return {"format": CHECKPOINT_FORMAT, "kind": obj["kind"], "model_config": mc, "ema": sd,
            "model": sd, "norm_mean": obj["norm_mean"], "norm_std": obj["norm_std"], "step": obj.get("step", 0)}


def lr_at(step: int, cfg: TrainConfig) -> float:
    """Linear warm-up, then cosine decay to lr_min at cfg.steps."""
    if step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    frac = min(1.0, (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup))
    return cfg.lr_min + 0.5 * (cfg.lr - cfg.lr_min) * (1 + math.cos(math.pi * frac))


@dataclass
class TrainResult:
    step: int
    last_loss: float | None
    losses: list[float]  # per step, this run, rank-mean
    val: dict[str, float] | None
    checkpoint: Path | None
    stopped_early: bool = False


class _StopFlag:
    """SIGINT/SIGTERM set a flag checked at step boundaries (a checkpoint is then written),
    instead of killing the process mid-optimiser-step."""

    def __init__(self) -> None:
        self.set = False
        self._old: dict[int, Any] = {}

    def __enter__(self) -> _StopFlag:
        if threading_main():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handler)
        return self

    def _handler(self, signum, frame) -> None:  # noqa: ARG002
        if self.set:  # second signal: give up immediately
            raise KeyboardInterrupt
        self.set = True

    def __exit__(self, *exc) -> None:
        for sig, h in self._old.items():
            signal.signal(sig, h)


def threading_main() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def train(cfg: TrainConfig, out_dir: str | os.PathLike, resume: bool = False,
          train_set: Dataset | None = None, val_set: Dataset | None = None,
          stop_after: int | None = None, progress: bool = True,
          log: Callable[[str], None] | None = None,
          init_from: str | os.PathLike | None = None) -> TrainResult:
    """Train (or resume) a model into ``out_dir``.

    Writes ``last.pt`` (full checkpoint: model, EMA, optimizer, step, config, normaliser,
    RNG scheme), ``model.pt`` (EMA weights for inference, see files.load_model) and
    ``train.jsonl`` (one JSON object per log/validation event). ``stop_after`` ends this
    run after that many total steps (with a checkpoint), as an interruption would;
    ``cfg.steps`` stays the schedule's horizon. Datasets default to ``cfg.data``.

    ``init_from`` (a ``last.pt`` of another run) starts a new run from that run's weights,
    EMA weights and normaliser, with a fresh optimiser and this config: fine-tuning a
    trained model on another mask distribution or loss costs a fraction of training anew.
    """
    out = Path(out_dir)
    d = init_distributed()
    if cfg.threads > 0:
        torch.set_num_threads(cfg.threads)
    log = log or (lambda s: print(s, file=sys.stderr))
    last = out / LAST
    if d.main:
        out.mkdir(parents=True, exist_ok=True)
    ckpt: dict | None = None
    if resume:
        if not last.exists():
            raise FileNotFoundError(f"--resume: no checkpoint {last}")
        ckpt = torch.load(last, map_location="cpu", weights_only=False)
        if ckpt.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"{last} is not an imucap training checkpoint")
        saved = TrainConfig.from_dict(ckpt["train_config"])
        # the run's identity comes from the checkpoint; only run-length/logging knobs may change
        keep = {"steps", "log_every", "ckpt_every", "val_every", "val_batches", "keep_every", "threads",
                "data", "infer_steps"}
        names = [f.name for f in fields(cfg)]
        merged = {k: (getattr(cfg, k) if k in keep else getattr(saved, k)) for k in names}
        cfg = TrainConfig(**merged)
    elif last.exists():
        raise FileExistsError(f"{last} exists; pass --resume to continue it or choose another --out")
    init: dict | None = None
    if init_from is not None and ckpt is None:
        init = torch.load(init_from, map_location="cpu", weights_only=False)
        if isinstance(init, dict) and init.get("format") == MODEL_FORMAT:
            init = init_from_model_file(init, window=cfg.model.window if cfg.kind == "diffusion" else None)
        if not isinstance(init, dict) or init.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"--init {init_from}: not an imucap training checkpoint (last.pt) or model file")
        # dropout is training behaviour, not architecture: a fine-tune may switch it
        init_model = replace(ModelConfig.from_dict(init["model_config"]), dropout=cfg.model.dropout)
        deeper = replace(init_model, layers=cfg.model.layers) == cfg.model and cfg.model.layers > init_model.layers
        grow = {k: True for k in ("points", "bypass") if getattr(cfg.model, k) and not getattr(init_model, k)}
        if grow.get("points") and not cfg.model.mask_input:
            grow = {}
        # reading tokens, a position input or a bypass added to a model without them start at
        # zero: the same model at first
        added = ((not init_model.readings and cfg.model.readings
                  and replace(init_model, readings=cfg.model.readings, reading=cfg.model.reading) == cfg.model)
                 or (bool(grow) and replace(init_model, **grow) == cfg.model))
        grown = (deeper or added) and cfg.kind == "diffusion"
        if init["kind"] != cfg.kind or (init_model != cfg.model and not grown):
            raise ValueError(f"--init {init_from}: its model ({init['kind']}, {init['model_config']}) "
                             f"differs from this config's ({cfg.kind}, {cfg.model.to_dict()})")

    data = cfg.data or default_data()
    if "train" not in data and train_set is None:
        raise ValueError("no training data: set data.train in the config")
    # rank 0 builds (and caches) the datasets first; the others then read the cache
    # instead of racing to build and write the same files
    for turn in (True, False):
        if d.main == turn:
            if train_set is None:
                train_set = load_dataset(data["train"], causal=cfg.causal)
            if val_set is None and data.get("val"):
                val_set = load_dataset(data["val"], causal=cfg.causal)
        barrier(d)

    if ckpt is not None or init is not None:
        src = ckpt if ckpt is not None else init
        mean_np, std_np = src["norm_mean"], src["norm_std"]
    elif cfg.teacher is not None:
        mean_np, std_np = teacher_normaliser(cfg)
    else:
        # our own statistics (not a dataset-provided normaliser): they must match the
        # augmentation, and they travel with every checkpoint and model file
        mean_np, std_np = window_stats(train_set, cfg.window, yaw_invariant=cfg.augment_yaw, seed=cfg.seed)
    ctx = StepContext(cfg, torch.as_tensor(mean_np, dtype=torch.float32),
                      torch.as_tensor(std_np, dtype=torch.float32), Schedule.cosine(cfg.T),
                      teacher=load_teacher(cfg, mean_np, std_np))

    torch.manual_seed(cfg.seed)  # identical initial weights on every rank
    model = build_model(cfg.kind, cfg.model).to(d.device)
    opt = torch.optim.AdamW(param_groups(model, cfg), lr=cfg.lr, weight_decay=cfg.weight_decay, betas=(0.9, 0.99))
    ema = EMA(model, cfg.ema_decay)
    start = 0
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        ema.load_state_dict(ckpt["ema"])
        start = int(ckpt["step"])
    elif init is not None:
        # start from the averaged weights (the better model) and keep averaging from there
        # a deeper diffusion model takes the trained layers and starts its extra ones as identities
        if init_model == cfg.model:
            state = init["ema"]
        elif added:
            state = {**model.state_dict(), **init["ema"]}
        else:
            state = deepened_state_dict(init["ema"], model)
        model.load_state_dict(state)
        ema.load_state_dict(state)
    net: nn.Module = model
    if d.enabled:
        from torch.nn.parallel import DistributedDataParallel as DDP

        net = DDP(model, device_ids=[d.local_rank] if d.device.type == "cuda" else None)
    per_rank = max(1, cfg.batch // d.world)
    train_readings = clip_readings(train_set, cfg)
    end = cfg.steps if stop_after is None else min(cfg.steps, stop_after)

    def save(step: int, val: dict | None) -> Path:
        obj = {
            "format": CHECKPOINT_FORMAT, "kind": cfg.kind, "step": step,
            "train_config": cfg.to_dict(), "model_config": cfg.model.to_dict(),
            "model": model.state_dict(), "ema": ema.state_dict(), "optimizer": opt.state_dict(),
            "norm_mean": np.asarray(mean_np), "norm_std": np.asarray(std_np),
            "rng": {"scheme": "per-step: SeedSequence([seed, rank, step])", "seed": cfg.seed,
                    "torch": torch.get_rng_state()},
            "world_size": d.world, "val": val, "time": time.time(),
        }
        atomic_torch_save(obj, last)
        if cfg.keep_every and step % cfg.keep_every == 0:
            atomic_torch_save(obj, out / kept_checkpoint_name(step))
        save_model(out / MODEL_FILE, ema.model, cfg.kind, mean_np, std_np, step=step,
                   meta={"val": val, "train_config": cfg.to_dict(), "default_steps": cfg.infer_steps,
                         "inpaint_mode": inpaint_mode_for(cfg), "acc_filter": "causal" if cfg.causal else "centred"})
        return last

    logf = open(out / LOG_FILE, "a") if d.main else None  # noqa: SIM115

    def write_log(obj: dict) -> None:
        if logf is not None:
            logf.write(json.dumps(obj) + "\n")
            logf.flush()

    if d.main:
        write_log({"event": "start", "step": start, "world": d.world, "kind": cfg.kind, "time": time.time(),
                   "params": sum(p.numel() for p in model.parameters()), "resume": ckpt is not None,
                   "init_from": str(init_from) if init is not None else None})
    pbar = None
    if progress and d.main:
        from tqdm import tqdm

        pbar = tqdm(total=end, initial=start, desc=f"train {cfg.kind}", unit="step", dynamic_ncols=True,
                    file=sys.stderr)
    losses: list[float] = []
    val: dict | None = ckpt.get("val") if ckpt else None
    ckpt_path: Path | None = None
    acc: dict[str, float] = {}
    n_acc = 0
    step = start
    stopped = False
    t_last = time.time()
    try:
        with _StopFlag() as stop:
            while step < end:
                net.train()
                rng, gen = step_seeds(cfg.seed, d.rank, step)
                batch = with_readings(train_set.sample(rng, per_rank, cfg.window), train_readings)
                lr = lr_at(step, cfg)
                for g in opt.param_groups:
                    g["lr"] = lr * g.get("lr_scale", 1.0)
                loss, terms = batch_loss(net, batch, ctx, rng, gen)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                if cfg.grad_clip > 0:
                    torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
                opt.step()
                ema.update(model, step)
                step += 1
                lv = float(loss.detach())
                if not math.isfinite(lv):
                    raise FloatingPointError(f"loss became {lv} at step {step}")
                losses.append(lv)
                for k, v in terms.items():
                    acc[k] = acc.get(k, 0.0) + v
                acc["loss"] = acc.get("loss", 0.0) + lv
                n_acc += 1
                if pbar is not None:
                    pbar.update(1)
                    pbar.set_postfix(loss=f"{lv:.4f}", refresh=False)
                if step % cfg.log_every == 0 or step == end:
                    keys = sorted(acc)
                    vals = all_reduce_mean([acc[k] / n_acc for k in keys], d)
                    now = time.time()
                    write_log({"event": "train", "step": step, "lr": lr, **dict(zip(keys, vals)),
                               "sec_per_step": (now - t_last) / n_acc, "time": now})
                    t_last, acc, n_acc = now, {}, 0
                if val_set is not None and cfg.val_every and (step % cfg.val_every == 0 or step == end):
                    if d.main:
                        val = validate(ema.model, val_set, ctx)
                        write_log({"event": "val", "step": step, **val, "time": time.time()})
                        if pbar is not None:
                            pbar.set_postfix(loss=f"{lv:.4f}", val=f"{val['val_loss']:.4f}",
                                             ga6=f"{val['val_ga6_deg']:.1f}")
                    barrier(d)
                want_stop = any_rank(stop.set, d)
                if step % cfg.ckpt_every == 0 or step == end or want_stop:
                    if d.main:
                        ckpt_path = save(step, val)
                        write_log({"event": "checkpoint", "step": step, "path": str(ckpt_path),
                                   "time": time.time()})
                    barrier(d)
                if want_stop:
                    stopped = True
                    if d.main:
                        log(f"stopped by signal at step {step}; resume with --resume")
                    break
    finally:
        if pbar is not None:
            pbar.close()
        if logf is not None:
            logf.close()
    if d.enabled:
        import torch.distributed as dist

        barrier(d)
        dist.destroy_process_group()
    return TrainResult(step=step, last_loss=losses[-1] if losses else None, losses=losses, val=val,
                       checkpoint=ckpt_path or (last if last.exists() else None), stopped_early=stopped)


def export_model(checkpoint: str | os.PathLike, dest: str | os.PathLike, fp16: bool = False,
                 default_steps: str | None = None, poser: dict | None = None, reading: str | None = None) -> None:
    """Write the EMA weights of a training checkpoint as an inference model file (what is
    shipped: fp16 halves it; files.load_model casts back to float32). ``poser``: the
    poser defaults to record with it (``inpaint_mode``, ``history``, ``noise``,
    ``contact_threshold``, ``mirror``; see Poser),
    chosen by whoever measured them on this model. ``reading``: the name in READINGS a
    model with reading tokens answers in when not told."""
    ck = torch.load(checkpoint, map_location="cpu", weights_only=False)
    if ck.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{checkpoint} is not an imucap training checkpoint")
    model = build_model(ck["kind"], with_reading(ModelConfig.from_dict(ck["model_config"]), reading))
    model.load_state_dict(ck["ema"])
    cfg = dict(ck["train_config"])
    steps = default_steps if default_steps is not None else cfg.get("infer_steps")
    meta = {"val": ck.get("val"), "train_config": cfg, "default_steps": steps,
            "inpaint_mode": inpaint_mode_for(TrainConfig.from_dict(cfg)),
            "acc_filter": "causal" if cfg.get("causal") else "centred"}
    if cfg.get("answer_lag"):  # trained to be best k frames back: the poser answers that late (inference/poser/lag.py)
        meta["answer_lag"] = int(cfg["answer_lag"])
    if cfg.get("symmetric_start"):  # trained from the symmetric midpoint: the poser starts there
        meta["symmetric_start"] = True
    meta.update(poser or {})
    save_model(dest, model, ck["kind"], ck["norm_mean"], ck["norm_std"], step=int(ck["step"]), meta=meta, fp16=fp16)


