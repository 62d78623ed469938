"""What every network of the model shares: its size configuration, the body-height
scaling, and atomic saving. Below both the denoiser and the regressor, so neither imports
the other."""

from __future__ import annotations

import os
import tempfile
from dataclasses import asdict, dataclass, fields

import torch
from torch import nn

from inference.features.layout import N_FEATURES, WINDOW

# Height is fed as a standardised scalar; these are typical adult statures (metres).
HEIGHT_MEAN = 1.70


HEIGHT_STD = 0.10

# The datasets' readings of a body a model can be told apart (ModelConfig.readings): each
# studio's marker set and skeleton solver put a segment's frame a few degrees off another's,
# and a model trained on several blends them. Index 0 is "not told".
READINGS = ("none", "bandai", "hdm05", "cmu")


@dataclass
class ModelConfig:
    """Size of a denoiser or regressor.

    The paper's model is ``ModelConfig.paper()`` (8 layers / 512 / FF 2048 / 8 heads).
    The default stays 4/256/1024 (other code and tests use it as "the default model");
    the CPU real-time size measured with benchmarks/bench_model.py is 4/128/512 (docs/model.md,
    "Model (issue 3)"): ~11 vs ~3.7 ms per model call on one core of this machine. The
    shipped model's size comes from its model file, not from this default.
    """

    layers: int = 4
    d_model: int = 128
    heads: int = 4
    ff: int = 512
    dropout: float = 0.1
    window: int = WINDOW
    features: int = N_FEATURES
    # x0 = sqrt(ab_t) z + sqrt(1 - ab_t) F(z, t, h) instead of x0 = F(z, t, h): the network
    # learns the residual (v-prediction in disguise), so at low noise the input passes
    # through unchanged instead of having to be re-learned. Without it, a CPU-sized
    # training budget left the model blurring even a clean input (18 deg at t = 0; docs/model.md).
    skip: bool = False
    # the frame tokens also read the per-feature known/unknown mask. Without it a model
    # trained by replacement (TrainConfig.cond_prob) must guess from the values alone
    # whether an entry is a clean measurement or noise, which a CPU budget did not teach.
    mask_input: bool = False
    # a reading token added to the height token (READINGS[1:]; 0 = no token): trained with
    # the window's dataset, or "none" in a share of windows (TrainConfig.reading_drop), so
    # the readings are learnt apart instead of averaged. ``reading`` is the one the model
    # answers in when not told (chosen at export), which is what the poser gets.
    readings: int = 0
    reading: int = 0
    # tracked VR points (headset, controllers, waist tracker) as a position input of every
    # frame token (``inference.body.tracked.point_features``: 16 numbers per frame, zeros
    # where absent). Zero at first, so a model fine-tuned from one without it starts as
    # that model; their orientations reach the model as known segment orientations.
    points: bool = False
    # a linear map from each frame's input (and mask) straight to its output, beside the
    # transformer. A narrow network squeezes a frame's 190 features through d_model numbers, and
    # the segments next to a worn one (a hand below a wrist sensor, the neck below the head, a
    # foot below a shank) are, to first order, that measurement turned by a constant: linear in
    # it, yet lost in the squeeze (a 64-wide chain student's hands were 15 deg behind its
    # teacher's on dg). Zero at first, so a model grown with it starts as the model it grew from.
    bypass: bool = False
    T: int = 1000

    @classmethod
    def paper(cls) -> ModelConfig:
        return cls(layers=8, d_model=512, heads=8, ff=2048)

    @classmethod
    def tiny(cls) -> ModelConfig:
        """For tests and smoke runs only."""
        return cls(layers=1, d_model=32, heads=2, ff=64, dropout=0.0)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        names = {f.name for f in fields(cls)}
        if d.get("hmr"):  # HAD's refinement stage, tried and removed (docs/model.md)
            raise ValueError("a model with HAD's refinement stage (hmr): the stage is no longer part of the denoiser")
        return cls(**{k: v for k, v in d.items() if k in names})


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def atomic_torch_save(obj: object, path: str | os.PathLike) -> None:
    """torch.save to a temporary file in the same directory, fsync, then os.replace, so a
    crash or kill mid-write never leaves a truncated file under the final name."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".pt", dir=d)
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(obj, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
