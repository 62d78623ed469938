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

Data interface (``FeatureDataset`` in inference/dataset.py, or ``ArrayDataset`` here):
``clips`` list of (T_i, 190) float32 unnormalised features, ``heights`` (n,), ``offsets``
(n, 24, 3), ``weights`` (n,), ``sample(rng, batch, window) -> {x, height, offsets}``.
"""

from __future__ import annotations

import copy
import functools
import importlib
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from inference.body.body import Body, anthropometric_offsets, contact_points, forward_kinematics
from inference.body.rotations import axis_angle_to_matrix, matrix_angle_between, matrix_to_rot6d, rot6d_to_matrix
from inference.body.skeleton import CONTACTS, METRIC_EXCLUDED, N_SEGMENTS, SEGMENT_INDEX, SEGMENTS, parse_sites
from inference.features.layout import (
    FPS_MODEL,
    N_FEATURES,
    SL_ACC,
    SL_CONTACT,
    SL_DP,
    SL_PZ,
    SL_ROT,
    WINDOW,
    observation_mask,
)
from inference.features.mirror import MirrorAveraged, mirror_features, mirror_points
from inference.model.denoiser import ModelConfig, atomic_torch_save, build_model, deepened_state_dict, save_model
from inference.model.diffusion import Schedule, inpaint, paper_steps, parse_steps
from inference.model.regressor import MaskConfig, random_observation_mask

CHECKPOINT_FORMAT = "imucap-train-v1"
LAST = "last.pt"
MODEL_FILE = "model.pt"
LOG_FILE = "train.jsonl"
STD_FLOOR = 1e-2  # features with less spread than this are treated as constant
VAL_SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")  # the paper's 6
_EVAL_SEGMENTS = [i for i in range(N_SEGMENTS) if i not in {SEGMENT_INDEX[s] for s in METRIC_EXCLUDED}]


# --------------------------------------------------------------------------- configuration

@dataclass
class LossWeights:
    """Weights of the loss terms. The terms are in these units:

    simple: normalised features (1 = one standard deviation); vel: 6D change per second;
    fk: metres; drift: metres; slide: metres per second. Defaults are the weights the
    shipped model was trained with (NOTES.md, "Training the shipped model"): each
    auxiliary term starts at ~0.1-0.3 of the simple term. Heavier weights (terms 10-50x
    the simple term at initialisation) stalled learning: the model never learned to
    reproduce even an un-noised input, because the random initial predictions give
    foot speeds of metres per second and 6D velocities of ~20 /s.
    """

    simple: float = 1.0
    vel: float = 0.002
    fk: float = 2.0
    drift: float = 0.05
    slide: float = 0.02
    # the live poser outputs only a window's last frame, the one without future context;
    # these repeat the simple and fk terms on that frame alone to spend more of a small
    # model's capacity there (0 = the paper's uniform weighting over the window)
    last: float = 0.0
    fk_last: float = 0.0
    # swing amplitude of the legs: per window, the spread over time of each knee, ankle and
    # toe position relative to the pelvis, predicted vs. true (metres). The pointwise terms
    # above are all minimised by the conditional mean, which under-flexes an unmeasured
    # thigh and shortens the stride the root correction walks (NOTES.md, sessions 11-12);
    # this term compares amplitudes, not positions, so it pulls the other way
    swing: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class TrainConfig:
    """Everything that defines a training run; saved in every checkpoint."""

    kind: str = "diffusion"  # or "regressor"
    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossWeights = field(default_factory=LossWeights)
    mask: MaskConfig = field(default_factory=MaskConfig)  # regressor; diffusion when cond_prob > 0
    # diffusion only: share of training windows noised only where unobserved (a mask drawn
    # from `mask`; observed entries stay clean), the rest noised everywhere as in the
    # paper. > 0 makes the shipped poser inpaint in "replace" mode (diffusion.inpaint).
    cond_prob: float = 0.0
    # diffusion only: levels drawn as t = (T + 1) * u ** (1 / t_power), u uniform; 1 = the
    # usual uniform draw, > 1 spends more of the training on the high-noise levels the
    # live step list (1000/700/400/10/0) relies on; at t ~ 0 an x0 model has little to learn
    t_power: float = 1.0
    # diffusion only: share of training windows whose level is one of the live step list
    # (``infer_steps``) instead of a random one. With 3 live steps (1000/400/0) the model is
    # only ever called at three levels; a small model trained uniformly spends ~99 % of its
    # samples elsewhere
    t_focus: float = 0.0
    # diffusion only: share of the windows drawn at the top level T whose noised entries hold
    # zeros (the prior's mean) instead of a draw: what a poser with noise "mean" feeds the
    # model at its first call (``inpaint(start="mean")``). 1 = the top level is trained only
    # that way, so its answer becomes the mean estimate of the unknown features
    mean_start: float = 0.0
    # sites whose orientations must be known for a window's swing loss term to count (by the
    # share of its frames, ``sites_known_share``); empty = every window alike. The swing term
    # asks for the true leg amplitude, which only the measurements can place: with the
    # shanks unseen (pelvis and wrists) the step's phase is a guess, and an amplitude forced
    # onto a guessed phase costs angle. With the pelvis unseen (shanks only) a short-step
    # walker already gets the typical stride, and the push adds to it; gating on the pelvis
    # too softened that only a little (NOTES.md, session 12)
    swing_gate: list[str] = field(default_factory=list)
    steps: int = 100_000  # total optimiser steps (also the horizon of the LR decay)
    batch: int = 64  # global batch (split over ranks)
    window: int = WINDOW
    lr: float = 2e-4
    lr_min: float = 1e-5
    warmup: int = 1000
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    ema_decay: float = 0.999
    augment_yaw: bool = True
    # share of training windows mirrored left <-> right (``mirror_features``): the data has
    # few actors, each with their own handedness and habits; a mirrored actor is a new one
    augment_mirror: float = 0.0
    # train the mirror-averaged model the poser runs (mirror.MirrorAveraged: every forward
    # pass also answers for the mirrored windows, in one batch of twice the size), so the
    # average, not each half, is what the loss shapes (NOTES.md "Session 13")
    mirror_average: bool = False
    # body-size augmentation: each window's body scaled by s, log-uniform in
    # [1 / (1 + a), 1 + a] (``scale_features``). The data has one body size per actor, so
    # without it the height token tells the model who is moving and it learns that
    # actor's habits (NOTES.md "Session 8")
    augment_scale: float = 0.0
    seed: int = 0
    T: int = 1000
    log_every: int = 50
    ckpt_every: int = 1000
    val_every: int = 1000
    val_batches: int = 8
    val_batch: int = 32
    keep_every: int = 0  # also keep step_XXXXXXX.pt every this many steps (0 = only last.pt)
    threads: int = 0  # torch intra-op threads per process (0 = leave torch's default)
    # step list the live poser should use with this model (written to model.pt as
    # meta["default_steps"]; anything diffusion.parse_steps takes); None = the paper's 10D
    infer_steps: str | None = None
    # {"train": spec, "val": spec}, see load_dataset; empty = default_data() (the split)
    data: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> TrainConfig:
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"unknown training config keys: {sorted(unknown)}")
        d = dict(d)
        if isinstance(d.get("model"), dict):
            d["model"] = ModelConfig.from_dict(d["model"])
        if isinstance(d.get("loss"), dict):
            d["loss"] = LossWeights(**d["loss"])
        if isinstance(d.get("mask"), dict):
            d["mask"] = MaskConfig.from_dict(d["mask"])
        cfg = cls(**d)
        if cfg.kind not in ("diffusion", "regressor"):
            raise ValueError(f"unknown model kind {cfg.kind!r}")
        # a misspelt site would otherwise surface as a KeyError at the first batch
        cfg.swing_gate = parse_sites(cfg.swing_gate)
        return cfg

    @classmethod
    def load(cls, path: str | os.PathLike) -> TrainConfig:
        with open(path) as f:
            return cls.from_dict(json.load(f))


# --------------------------------------------------------------------------- data

class Dataset(Protocol):
    clips: list[np.ndarray]
    heights: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray

    def sample(self, rng: np.random.Generator, batch: int, window: int = WINDOW) -> dict: ...


class ArrayDataset:
    """A minimal in-memory dataset with the FeatureDataset interface.

    Used for tests, smoke runs and cached feature files (``.npz`` with ``features``
    (sum T_i, 190), ``lengths``, ``heights``, ``offsets`` and optional ``weights``).
    Clips shorter than the window are padded at the end by holding the last pose still
    (zero acceleration, zero displacement), which is what a subject standing still
    would produce.
    """

    def __init__(self, clips: list[np.ndarray], heights: np.ndarray, offsets: np.ndarray,
                 weights: np.ndarray | None = None) -> None:
        self.clips = [np.asarray(c, np.float32) for c in clips]
        self.heights = np.asarray(heights, np.float32)
        self.offsets = np.asarray(offsets, np.float32)
        w = np.ones(len(self.clips)) if weights is None else np.asarray(weights, np.float64)
        self.weights = w / w.sum()

    def __len__(self) -> int:
        return len(self.clips)

    def sample(self, rng: np.random.Generator, batch: int, window: int = WINDOW) -> dict:
        idx = rng.choice(len(self.clips), size=batch, p=self.weights)
        x = np.empty((batch, window, N_FEATURES), np.float32)
        for b, i in enumerate(idx):
            c = self.clips[i]
            if len(c) >= window:
                s = int(rng.integers(0, len(c) - window + 1))
                x[b] = c[s:s + window]
            else:
                x[b, : len(c)] = c
                x[b, len(c):] = c[-1]
                x[b, len(c):, SL_ACC] = 0.0
                x[b, len(c):, SL_DP] = 0.0
        return {"x": x, "height": self.heights[idx].copy(), "offsets": self.offsets[idx].copy()}

    @classmethod
    def load_npz(cls, path: str | os.PathLike) -> ArrayDataset:
        with np.load(path) as z:
            lengths = z["lengths"].astype(int)
            clips = np.split(z["features"], np.cumsum(lengths)[:-1])
            return cls(clips, z["heights"], z["offsets"], z["weights"] if "weights" in z else None)

    def save_npz(self, path: str | os.PathLike) -> None:
        np.savez(path, features=np.concatenate(self.clips), lengths=np.array([len(c) for c in self.clips]),
                 heights=self.heights, offsets=self.offsets, weights=self.weights)


def synthetic_dataset(clips: int = 8, frames: int = 90, seed: int = 0) -> ArrayDataset:
    """Random but smooth feature clips with the right layout and plausible magnitudes.

    For tests and smoke runs of the training machinery only: orientations are smooth
    random rotations, not human poses, and accelerations are not consistent with them.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / FPS_MODEL
    out, heights, offsets = [], [], []
    for _ in range(clips):
        x = np.zeros((frames, N_FEATURES), np.float32)
        freq = rng.uniform(0.2, 1.5, size=(1, N_SEGMENTS, 3))
        phase = rng.uniform(0, 2 * np.pi, size=(1, N_SEGMENTS, 3))
        amp = rng.uniform(0.05, 0.5, size=(1, N_SEGMENTS, 3))
        rotvec = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
        rotvec[:, 0, 2] += rng.uniform(-np.pi, np.pi) + 0.3 * t  # heading drifts
        R = axis_angle_to_matrix(rotvec)
        x[:, SL_ROT] = matrix_to_rot6d(R).reshape(frames, -1)
        x[:, SL_ACC] = (rng.uniform(0.5, 3) * np.sin(2 * np.pi * rng.uniform(0.3, 2, 39) * t[:, None]
                                                     + rng.uniform(0, 6, 39))).astype(np.float32)
        speed = rng.uniform(0, 1.5)
        heading = R[:, 0, :2, 0]
        x[:, SL_DP] = speed / FPS_MODEL * heading
        x[:, SL_PZ] = 0.9 + 0.02 * np.sin(2 * np.pi * t)[:, None]
        x[:, SL_CONTACT] = (np.sin(2 * np.pi * 1.0 * t[:, None] + np.array([0, 0.3, np.pi, np.pi + 0.3])) > 0)
        h = rng.uniform(1.55, 1.95)
        out.append(x)
        heights.append(h)
        offsets.append(anthropometric_offsets(h))
    energy = np.array([float(np.mean(np.square(c[:, SL_DP]))) + 1e-3 for c in out])
    return ArrayDataset(out, np.array(heights), np.array(offsets), energy)


REPO_ROOT = Path(__file__).resolve().parents[2]
# the split: Bandai + HDM05 actors bd, bk for training; actor dg held out
DEFAULT_TRAIN_MOTION = ("bandai", "hdm05/bd", "hdm05/bk")
DEFAULT_VAL_MOTION = ("hdm05/dg",)


def data_root() -> Path:
    """The real motion data: $IMUCAP_DATA, else ../shared/data beside the checkout."""
    return Path(os.environ.get("IMUCAP_DATA", REPO_ROOT.parent / "shared" / "data"))


def cache_root() -> Path:
    """Where built feature datasets are cached: $IMUCAP_CACHE, else <checkout>/cache (ignored by git)."""
    return Path(os.environ.get("IMUCAP_CACHE", REPO_ROOT / "cache"))


def default_data() -> dict:
    return {"train": {"motion": list(DEFAULT_TRAIN_MOTION)}, "val": {"motion": list(DEFAULT_VAL_MOTION)}}


def load_dataset(spec: dict | str) -> Dataset:
    """Build a dataset from a config entry.

    - ``{"motion": [path, ...], "cache_dir": optional}``: every motion file under those
      paths (relative ones are taken under ``data_root()``) through
      ``inference.dataset.build_dataset`` (cached under ``cache_root()``);
    - ``{"factory": "module:callable", "kwargs": {...}}`` calls that and uses the result;
    - ``{"npz": path}`` or a plain path string loads an ``ArrayDataset`` cache;
    - ``{"synthetic": {"clips": 8, "frames": 90, "seed": 0}}`` makes a synthetic one.
    """
    if isinstance(spec, str | os.PathLike):
        spec = {"npz": os.fspath(spec)}
    if "motion" in spec:
        from inference.training.dataset import build_dataset

        paths = [p if Path(p).is_absolute() else data_root() / p for p in spec["motion"]]
        return build_dataset(paths, spec.get("cache_dir") or cache_root(),
                             progress=bool(spec.get("progress", True)))
    if "factory" in spec:
        mod_name, _, attr = spec["factory"].partition(":")
        obj: Any = importlib.import_module(mod_name)
        for part in attr.split("."):
            obj = getattr(obj, part)
        return obj(**spec.get("kwargs", {}))
    if "npz" in spec:
        return ArrayDataset.load_npz(spec["npz"])
    if "synthetic" in spec:
        return synthetic_dataset(**spec["synthetic"])
    raise ValueError(f"cannot build a dataset from {spec!r} (need motion, factory, npz or synthetic)")


def _horizontal_pairs() -> list[tuple[int, int]]:
    """Indices (x, y) of every horizontal vector component pair in the frame layout: the
    two 6D columns of each segment, each site acceleration, and dp."""
    pairs = []
    for start, n in ((SL_ROT.start, 2 * N_SEGMENTS), (SL_ACC.start, (SL_ACC.stop - SL_ACC.start) // 3)):
        pairs += [(start + 3 * k, start + 3 * k + 1) for k in range(n)]
    pairs.append((SL_DP.start, SL_DP.start + 1))
    return pairs


def feature_stats(clips: list[np.ndarray], yaw_invariant: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Per-feature mean and std over all frames, std floored at STD_FLOOR.

    With ``yaw_invariant`` (what training with random-heading augmentation needs) every
    horizontal (x, y) pair gets mean 0 and the common std sqrt(E[x^2 + y^2] / 2): the
    statistics of the data turned to a uniformly random heading. Plain statistics would
    give e.g. a thigh's nearly constant forward component a tiny std, and after a random
    turn that feature would sit hundreds of "standard deviations" away.
    """
    allx = np.concatenate([np.asarray(c, np.float64) for c in clips])
    mean = allx.mean(0)
    std = allx.std(0)
    if yaw_invariant:
        for i, j in _horizontal_pairs():
            mean[i] = mean[j] = 0.0
            std[i] = std[j] = math.sqrt(float(np.mean(allx[:, i] ** 2 + allx[:, j] ** 2)) / 2)
    return mean.astype(np.float32), np.maximum(std, STD_FLOOR).astype(np.float32)


def window_stats(ds: Dataset, window: int = WINDOW, yaw_invariant: bool = True, seed: int = 0,
                 n_windows: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """``feature_stats`` over windows drawn by the dataset's own sampler, i.e. over the
    distribution the model is trained on (kinetic-energy weighting favours lively clips,
    whose accelerations are ~1.8x larger in std than the frame average on HDM05)."""
    rng = np.random.default_rng([seed, 7919])
    xs = [ds.sample(rng, 256, window)["x"].reshape(-1, N_FEATURES) for _ in range(max(1, n_windows // 256))]
    return feature_stats(xs, yaw_invariant=yaw_invariant)


# --------------------------------------------------------------------------- augmentation

def rotate_yaw(x: Tensor, angle: Tensor) -> Tensor:
    """Rotate windows (B, N, F) of unnormalised features about the world vertical by
    ``angle`` (B,) radians: orientations (both 6D columns), site accelerations and root
    displacement turn together; height and contacts are unchanged.

    Heading is arbitrary in the data (it depends on where each capture faced), so the
    model should not learn it; this also multiplies the effective data.
    """
    c = torch.cos(angle).to(x.dtype)[:, None, None]
    s = torch.sin(angle).to(x.dtype)[:, None, None]
    idx = torch.tensor(_horizontal_pairs())
    xi, yi = idx[:, 0], idx[:, 1]
    out = x.clone()
    vx, vy = x[..., xi], x[..., yi]
    out[..., xi] = c * vx - s * vy
    out[..., yi] = s * vx + c * vy
    return out


def scale_features(x: Tensor, scale: Tensor) -> Tensor:
    """Windows (B, N, F) of unnormalised features of the same motion on a body ``scale``
    (B,) times as large (``Motion.scaled``): site accelerations (gravity-free), root
    displacement and root height scale, orientations do not. Contact labels are kept: a
    planted foot of a larger body is still planted, though its 0.3 m/s label threshold
    would move a few borderline frames."""
    out = x.clone()
    s = scale.to(x.dtype)[:, None, None]
    for sl in (SL_ACC, SL_DP, SL_PZ):
        out[..., sl] = x[..., sl] * s
    return out


# --------------------------------------------------------------------------- losses

def contact_offsets_for(offsets: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(B, 4, 3) heel/toe points of each sample's body (as the body model places them)."""
    return np.stack([Body.from_offsets(o, float(h)).contact_offsets for o, h in zip(offsets, heights)])


def sites_known_share(known: Tensor, sites: list[str] | tuple[str, ...]) -> Tensor:
    """(B,) share of each window's frames in which every one of `sites` has its orientation
    known, from a (B, N, F) known-entry mask: the swing term's per-window weight
    (``TrainConfig.swing_gate``)."""
    return known[..., _orientation_columns(tuple(sites))].all(-1).float().mean(-1)


@functools.lru_cache(maxsize=8)
def _orientation_columns(sites: tuple[str, ...]) -> Tensor:
    """Feature columns of the sites' orientations, built once: the gate runs on every
    training step (the accelerations come with the orientations, so they need no check)."""
    cols = observation_mask(list(sites))
    cols[SL_ROT.stop:] = False
    return torch.as_tensor(cols)


# knees, ankles and toes: the origins of the shank, foot and toe segments
_LEG_JOINTS = [SEGMENT_INDEX[n] for n in ("l_shank", "r_shank", "l_foot", "r_foot", "l_toes", "r_toes")]


def motion_losses(pred_n: Tensor, true_n: Tensor, mean: Tensor, std: Tensor, offsets: Tensor,
                  contact_local: Tensor, swing_weight: Tensor | None = None) -> dict[str, Tensor]:
    """Unweighted loss terms (scalars) for predicted vs. true normalised windows (B, N, F).

    offsets (B, 24, 3) rest bone offsets; contact_local (B, 4, 3) heel/toe points on their
    segments. swing_weight (B,) weighs each window's swing term (``sites_known_share``; None =
    1 for all). See ``LossWeights`` for the units.
    """
    B, N, _ = pred_n.shape
    pred = pred_n * std + mean
    true = true_n * std + mean
    terms: dict[str, Tensor] = {"simple": F.mse_loss(pred_n, true_n)}

    r6p = pred[..., SL_ROT].reshape(B, N, N_SEGMENTS, 6)
    r6t = true[..., SL_ROT].reshape(B, N, N_SEGMENTS, 6)
    dv = (r6p[:, 1:] - r6p[:, :-1]) - (r6t[:, 1:] - r6t[:, :-1])
    terms["vel"] = (dv * FPS_MODEL).square().sum(-1).mean()

    Rp = rot6d_to_matrix(r6p)
    Rt = rot6d_to_matrix(r6t)
    off = offsets[:, None].to(pred.dtype)
    zero = torch.zeros(B, N, 3, dtype=pred.dtype)
    jp = forward_kinematics(Rp, zero, off)
    jt = forward_kinematics(Rt, zero, off)
    fk_err = (jp - jt).square().sum(-1)
    terms["fk"] = fk_err.mean()
    terms["last"] = F.mse_loss(pred_n[:, -1], true_n[:, -1])
    terms["fk_last"] = fk_err[:, -1].mean()

    lp, lt = jp[:, :, _LEG_JOINTS], jt[:, :, _LEG_JOINTS]
    spread_p = (lp.var(dim=1, unbiased=False) + 1e-8).sqrt()  # eps: no inf gradient at rest
    spread_t = (lt.var(dim=1, unbiased=False) + 1e-8).sqrt()
    swing = (spread_p - spread_t).square().sum(-1).mean(-1)  # (B,)
    terms["swing"] = swing.mean() if swing_weight is None else (swing_weight * swing).mean()

    pp = torch.cumsum(pred[..., SL_DP], dim=1)
    pt = torch.cumsum(true[..., SL_DP], dim=1)
    terms["drift"] = (pp - pt).square().sum(-1).mean()

    # foot slide: predicted contact at frame i x world velocity of that foot point from
    # frame i to i+1 (relative FK motion + root displacement of frame i+1 + root height
    # change). The contact weight is detached: this term should move the feet, not
    # teach the model to predict "no contact" (the simple term supervises contacts).
    cp = contact_points(Rp, jp, contact_local[:, None].to(pred.dtype))  # (B, N, 4, 3)
    root_step = torch.cat([pred[:, 1:, SL_DP], pred[:, 1:, SL_PZ] - pred[:, :-1, SL_PZ]], dim=-1)
    v = (cp[:, 1:] - cp[:, :-1] + root_step[:, :, None]) * FPS_MODEL
    w = pred[:, :-1, SL_CONTACT].clamp(0.0, 1.0).detach()
    terms["slide"] = (w * v.square().sum(-1)).mean()
    return terms


def inpaint_mode_for(cfg: TrainConfig) -> str:
    """How a model trained with `cfg` should inpaint: the way it saw known entries."""
    return "replace" if cfg.kind == "diffusion" and cfg.cond_prob > 0 else "paper"


def total_loss(terms: dict[str, Tensor], weights: LossWeights) -> Tensor:
    return sum(getattr(weights, k) * v for k, v in terms.items())


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
    if cfg.mirror_average:
        model = MirrorAveraged(model, ctx.mean, ctx.std)
    m = None  # known entries, where the model is told them
    if cfg.kind == "diffusion":
        t = training_levels(cfg, B, gen, ctx.schedule.T)
        noise = torch.randn(xn.shape, generator=gen)
        if cfg.mean_start > 0:
            top = (t == ctx.schedule.T) & (torch.rand(B, generator=gen) < cfg.mean_start)
            noise = torch.where(top[:, None, None], torch.zeros(()), noise)
        z = ctx.schedule.q_sample(xn, t, noise=noise)
        if cfg.cond_prob > 0:
            # conditioning by replacement: known entries clean in z (and exact in the
            # output), so the loss is spent on what inpainting has to infer
            m = torch.as_tensor(random_observation_mask(rng, B, x.shape[1], cfg.mask))
            m &= torch.as_tensor(rng.random(B) < cfg.cond_prob)[:, None, None]
            z = torch.where(m, xn, z)
            out = model(z, t, height, m) if cfg.model.mask_input else model(z, t, height)
            pred = torch.where(m, xn, out)
        else:
            pred = model(z, t, height)
    else:
        m = torch.as_tensor(random_observation_mask(rng, B, x.shape[1], cfg.mask))
        pred = model(torch.where(m, xn, torch.zeros(())), m, height)
    gate = sites_known_share(m, cfg.swing_gate) if cfg.swing_gate and m is not None else None
    terms = motion_losses(pred, xn, ctx.mean, ctx.std, offsets, contact_local, gate)
    loss = total_loss(terms, cfg.loss)
    return loss, {k: float(v.detach()) for k, v in terms.items()}


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
    for i in range(cfg.val_batches):
        rng, gen = step_seeds(cfg.seed + 1_000_003, 0, i)
        batch = val_set.sample(rng, cfg.val_batch, cfg.window)
        _, terms = batch_loss(model, batch, ctx, rng, gen)
        for k, v in terms.items():
            sums[k] = sums.get(k, 0.0) + v
        sums["loss"] = sums.get("loss", 0.0) + sum(getattr(cfg.loss, k) * v for k, v in terms.items())
        x = torch.as_tensor(batch["x"], dtype=torch.float32)
        xn = (x - ctx.mean) / ctx.std
        h = torch.as_tensor(batch["height"], dtype=torch.float32)
        mask = torch.ones_like(xn, dtype=torch.bool)
        mask[:, -1] = obs
        x_in = xn.clone()
        x_in[:, -1] = torch.where(obs, xn[:, -1], xn[:, -2])
        if cfg.kind == "diffusion":
            out = inpaint(model, x_in, mask, h, paper_steps(), generator=gen, schedule=ctx.schedule,
                          mode=inpaint_mode_for(cfg), start="mean" if cfg.mean_start > 0 else "sample")
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

@dataclass
class Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0
    device: torch.device = field(default_factory=lambda: torch.device("cpu"))

    @property
    def enabled(self) -> bool:
        return self.world > 1

    @property
    def main(self) -> bool:
        return self.rank == 0


def init_distributed() -> Dist:
    """Join the process group when launched by torchrun (WORLD_SIZE > 1): gloo on CPU,
    nccl when CUDA is available. A single process needs no group at all."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        dev = torch.device("cuda") if torch.cuda.is_available() else torch.device("cpu")
        return Dist(device=dev)
    import torch.distributed as dist

    local = int(os.environ.get("LOCAL_RANK", "0"))
    if torch.cuda.is_available():
        torch.cuda.set_device(local)
        backend, dev = "nccl", torch.device("cuda", local)
    else:
        backend, dev = "gloo", torch.device("cpu")
    if not dist.is_initialized():
        dist.init_process_group(backend=backend)
    return Dist(rank=dist.get_rank(), world=dist.get_world_size(), local_rank=local, device=dev)


def _all_reduce_mean(values: list[float], d: Dist) -> list[float]:
    if not d.enabled:
        return values
    import torch.distributed as dist

    t = torch.tensor(values, dtype=torch.float64, device=d.device)
    dist.all_reduce(t)
    return (t / d.world).tolist()


def _any_rank(flag: bool, d: Dist) -> bool:
    if not d.enabled:
        return flag
    import torch.distributed as dist

    t = torch.tensor([1.0 if flag else 0.0], device=d.device)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return bool(t.item() > 0)


def _barrier(d: Dist) -> None:
    if d.enabled:
        import torch.distributed as dist

        dist.barrier()


# --------------------------------------------------------------------------- the trainer

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
    RNG scheme), ``model.pt`` (EMA weights for inference, see denoiser.load_model) and
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
        if init.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"--init {init_from}: not an imucap training checkpoint (last.pt)")
        # dropout is training behaviour, not architecture: a fine-tune may switch it
        init_model = replace(ModelConfig.from_dict(init["model_config"]), dropout=cfg.model.dropout)
        deeper = replace(init_model, layers=cfg.model.layers) == cfg.model and cfg.model.layers > init_model.layers
        if init["kind"] != cfg.kind or (init_model != cfg.model and not (deeper and cfg.kind == "diffusion")):
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
                train_set = load_dataset(data["train"])
            if val_set is None and data.get("val"):
                val_set = load_dataset(data["val"])
        _barrier(d)

    if ckpt is not None or init is not None:
        src = ckpt if ckpt is not None else init
        mean_np, std_np = src["norm_mean"], src["norm_std"]
    else:
        # our own statistics (not a dataset-provided normaliser): they must match the
        # augmentation, and they travel with every checkpoint and model file
        mean_np, std_np = window_stats(train_set, cfg.window, yaw_invariant=cfg.augment_yaw, seed=cfg.seed)
    ctx = StepContext(cfg, torch.as_tensor(mean_np, dtype=torch.float32),
                      torch.as_tensor(std_np, dtype=torch.float32), Schedule.cosine(cfg.T))

    torch.manual_seed(cfg.seed)  # identical initial weights on every rank
    model = build_model(cfg.kind, cfg.model).to(d.device)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, betas=(0.9, 0.99))
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
        state = init["ema"] if init_model == cfg.model else deepened_state_dict(init["ema"], model)
        model.load_state_dict(state)
        ema.load_state_dict(state)
    net: nn.Module = model
    if d.enabled:
        from torch.nn.parallel import DistributedDataParallel as DDP

        net = DDP(model, device_ids=[d.local_rank] if d.device.type == "cuda" else None)
    per_rank = max(1, cfg.batch // d.world)
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
            atomic_torch_save(obj, out / f"step_{step:07d}.pt")
        save_model(out / MODEL_FILE, ema.model, cfg.kind, mean_np, std_np, step=step,
                   meta={"val": val, "train_config": cfg.to_dict(), "default_steps": cfg.infer_steps,
                         "inpaint_mode": inpaint_mode_for(cfg)})
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
                batch = train_set.sample(rng, per_rank, cfg.window)
                lr = lr_at(step, cfg)
                for g in opt.param_groups:
                    g["lr"] = lr
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
                    vals = _all_reduce_mean([acc[k] / n_acc for k in keys], d)
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
                    _barrier(d)
                want_stop = _any_rank(stop.set, d)
                if step % cfg.ckpt_every == 0 or step == end or want_stop:
                    if d.main:
                        ckpt_path = save(step, val)
                        write_log({"event": "checkpoint", "step": step, "path": str(ckpt_path),
                                   "time": time.time()})
                    _barrier(d)
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

        _barrier(d)
        dist.destroy_process_group()
    return TrainResult(step=step, last_loss=losses[-1] if losses else None, losses=losses, val=val,
                       checkpoint=ckpt_path or (last if last.exists() else None), stopped_early=stopped)


def export_model(checkpoint: str | os.PathLike, dest: str | os.PathLike, fp16: bool = False,
                 default_steps: str | None = None, poser: dict | None = None) -> None:
    """Write the EMA weights of a training checkpoint as an inference model file (what is
    shipped: fp16 halves it; denoiser.load_model casts back to float32). ``poser``: the
    poser defaults to record with it (``inpaint_mode``, ``history``, ``noise``,
    ``contact_threshold``, ``mirror``; see Poser),
    chosen by whoever measured them on this model."""
    ck = torch.load(checkpoint, map_location="cpu", weights_only=False)
    if ck.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{checkpoint} is not an imucap training checkpoint")
    model = build_model(ck["kind"], ModelConfig.from_dict(ck["model_config"]))
    model.load_state_dict(ck["ema"])
    cfg = dict(ck["train_config"])
    steps = default_steps if default_steps is not None else cfg.get("infer_steps")
    meta = {"val": ck.get("val"), "train_config": cfg, "default_steps": steps,
            "inpaint_mode": inpaint_mode_for(TrainConfig.from_dict(cfg))}
    meta.update(poser or {})
    save_model(dest, model, ck["kind"], ck["norm_mean"], ck["norm_std"], step=int(ck["step"]), meta=meta, fp16=fp16)


__all__ = [
    "export_model",
    "LossWeights", "TrainConfig", "ArrayDataset", "synthetic_dataset", "load_dataset", "feature_stats",
    "window_stats", "data_root", "cache_root", "default_data",
    "rotate_yaw", "motion_losses", "total_loss", "EMA", "step_seeds", "batch_loss", "validate",
    "init_distributed", "lr_at", "train", "TrainResult", "CHECKPOINT_FORMAT",
]
