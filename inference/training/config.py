"""What a training run is: its configuration, loss weights and file names. Read by the
loop, the data and the command line; a config file is this dataclass as JSON."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field, fields

from inference.body.skeleton import parse_sites
from inference.features.layout import (
    WINDOW,
)
from inference.model.config import ModelConfig
from inference.model.regressor import MaskConfig

CHECKPOINT_FORMAT = "imucap-train-v1"


LAST = "last.pt"


MODEL_FILE = "model.pt"


LOG_FILE = "train.jsonl"


STD_FLOOR = 1e-2  # features with less spread than this are treated as constant


VAL_SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")  # the paper's 6


@dataclass
class LossWeights:
    """Weights of the loss terms. The terms are in these units:

    simple: normalised features (1 = one standard deviation); vel: 6D change per second;
    fk: metres; drift: metres; slide: metres per second. Defaults are the weights the
    shipped model was trained with (docs/model.md, "Training"): each
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
    # thigh and shortens the stride the root correction walks (docs/model.md, "Losses");
    # this term compares amplitudes, not positions, so it pulls the other way
    swing: float = 0.0
    # a chain student's answer to each state's mirror image against the mirror of its answer
    # (normalised features, the unknown entries): a student that answers one window a pose
    # has no mirror pair to cancel a left/right bias of its own (docs/model.md, "The fast model")
    mirror: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class SensorEffects:
    """What real, calibrated sensors add to the measured features and clean synthesis does
    not (docs/real_signals.md): drawn per window and site, applied to the inputs the model
    is told while its targets stay the true motion. All zero = off.

    p: share of windows that get them. mount_deg: residual sensor-to-bone rotation after
    calibration (random axis, angle uniform in [0, mount_deg]; skin and strap move over the
    muscle). heading_deg: residual heading of the sensor's world frame, uniform in
    [-h, h] (orientation and acceleration turn together). acc_gain: acceleration scaled by
    1 + uniform [-g, g] (a sensor higher or lower on the segment than the synthesized site);
    acc_scale: the centre of that gain (the model then reads real accelerations as larger:
    it did better on the real logs with theirs scaled up, docs/real_signals.md).
    acc_noise: white noise std on the model-rate acceleration (m/s^2). lag_frames: the
    site's signals shifted in time by uniform [-l, l] model frames (clocks of separate
    sensors aligned by their timestamps).
    """

    p: float = 0.0
    mount_deg: float = 0.0
    heading_deg: float = 0.0
    acc_gain: float = 0.0
    acc_noise: float = 0.0
    lag_frames: float = 0.0
    acc_scale: float = 1.0

    @property
    def active(self) -> bool:
        return self.p > 0 and (self.acc_scale != 1.0 or any(v > 0 for v in (
            self.mount_deg, self.heading_deg, self.acc_gain, self.acc_noise, self.lag_frames)))

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
    # diffusion only, with mean_start: the mean start sits at the data mean's symmetric midpoint
    # (``diffusion.symmetric_start``) instead of the data mean, as the poser starts a file whose
    # meta says ``symmetric_start`` (exported with it). The data mean is not its own mirror
    # image; a one-window student trained from it answers a symmetric body with a left/right
    # bias (docs/model.md, "The fast model")
    symmetric_start: bool = False
    # sites whose orientations must be known for a window's swing loss term to count (by the
    # share of its frames, ``sites_known_share``); empty = every window alike. The swing term
    # asks for the true leg amplitude, which only the measurements can place: with the
    # shanks unseen (pelvis and wrists) the step's phase is a guess, and an amplitude forced
    # onto a guessed phase costs angle. With the pelvis unseen (shanks only) a short-step
    # walker already gets the typical stride, and the push adds to it; gating on the pelvis
    # too softened that only a little (docs/model.md, "Losses")
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
    # average, not each half, is what the loss shapes (docs/model.md, "Augmentation")
    mirror_average: bool = False
    # body-size augmentation: each window's body scaled by s, log-uniform in
    # [1 / (1 + a), 1 + a] (``scale_features``). The data has one body size per actor, so
    # without it the height token tells the model who is moving and it learns that
    # actor's habits (docs/model.md, "Conditioning, masks and noise levels")
    augment_scale: float = 0.0
    # for models with reading tokens (ModelConfig.readings): share of windows told no
    # reading, so the model also answers untold (docs/model.md, "What the CMU runs say")
    reading_drop: float = 0.0
    # the reading tokens' learning rate as a multiple of the schedule's: a fine-tune that adds
    # them at a fine-tune's rate left them at ~1/30 of the height token's norm after 2500 steps
    reading_lr_scale: float = 1.0
    # for models with a position input (ModelConfig.points): share of the conditioned
    # windows that have a headset and two controllers tracked, and of those the share with a
    # waist tracker too (inference/training/points.py); the rest have none, so the model
    # stays what it was for IMUs alone
    points_share: float = 0.6
    points_pelvis: float = 0.3
    # the position input layer's learning rate as a multiple of the schedule's: at a
    # fine-tune's 1e-4 it grew to a quarter of the other inputs' weight norm in 2000 steps
    points_lr_scale: float = 1.0
    # parameter name prefixes to train (e.g. ["points_proj."]); every other parameter is frozen.
    # Empty: train all. A stage grown onto a trained model and trained alone has that
    # model as its exact control (docs/model.md, "HAD's hierarchical refinement")
    train_only: list[str] = field(default_factory=list)
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
    # accelerations through the trailing (causal) moving average of the low-latency live mode
    # instead of the centred one: the model then reads what `--latency low` feeds it. Passed to
    # the data (load_dataset) and written to the model file (meta "acc_filter"), from which the
    # poser's pipeline picks its resampler (docs/latency.md)
    causal: bool = False
    # the measured features as real sensors give them (``SensorEffects``; off by default)
    sensor_effects: SensorEffects = field(default_factory=SensorEffects)
    # diffusion only: distillation. A model file whose live answer is the target instead of
    # the truth: its own chain (``teacher_steps``, mean start, replacement of the known
    # entries, one window, no mirror unless ``teacher_mirror_chains``) on each training window of ``window`` frames; the
    # student answers in one call at the top level from the newest ``model.window`` frames of
    # it. One call trained on the truth learns the mean of what the sensors allow (a stand
    # between standing and sitting comes out bent); trained on the chain's answer it learns
    # the chain's choice (docs/model.md, "One step")
    teacher: str | None = None
    teacher_steps: str = "10D:3"
    # the target is the teacher's answer averaged over the window and its mirror image, each
    # a whole chain (as ``Poser(mirror_chains=True)`` answers live): a student that learns it
    # is near mirror-equivariant itself and can answer live without averaging, one window a
    # pose instead of two
    teacher_mirror_chains: bool = False
    # the teacher's weight in the target where the entries are unknown, the truth taking the
    # rest: 1 distils the chain's choice, 0 is the one call trained on the truth (its mean
    # answer keeps dg, loses the real stands); between, the student leans on the teacher
    # where the sensors leave a choice and on the truth where the teacher's chain errs
    teacher_share: float = 1.0
    # the student answers with a chain of its own at these levels (e.g. "10D:3", as the
    # shipped poser does) instead of one call: each of its calls is trained on the
    # teacher's call (mirror-averaged with ``teacher_mirror_chains``) at the very state the
    # student's own chain reached, so the student keeps the chain's choice among the poses
    # the sensors allow while its network may be narrower than the teacher's. A student of
    # another size starts from fresh weights with the teacher's normaliser (no ``--init``)
    student_steps: str | None = None
    # the frame the "last" loss terms weigh, counted back from the newest: 0 for the live
    # poser, which shows the newest frame; k for a model that answers k frames late (an
    # import or replay, which has no need to answer at once, can show the answer for a frame
    # with k frames of the worn sensors after it: docs/real_signals.md, "The thighs stage by
    # stage")
    answer_lag: int = 0

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
        if isinstance(d.get("sensor_effects"), dict):
            d["sensor_effects"] = SensorEffects(**d["sensor_effects"])
        cfg = cls(**d)
        if cfg.kind not in ("diffusion", "regressor"):
            raise ValueError(f"unknown model kind {cfg.kind!r}")
        if not 0 <= cfg.answer_lag < cfg.window:
            raise ValueError(f"answer_lag {cfg.answer_lag}: frames back from the newest, 0 to {cfg.window - 1}")
        # a misspelt site would otherwise surface as a KeyError at the first batch
        cfg.swing_gate = parse_sites(cfg.swing_gate)
        return cfg

    @classmethod
    def load(cls, path: str | os.PathLike) -> TrainConfig:
        with open(path) as f:
            return cls.from_dict(json.load(f))
