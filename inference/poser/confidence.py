"""How sure the poser is of each segment: the spread of other inpaintings of the same window.

A clinician reading a knee angle must know whether a sensor measured it or the model
guessed it, and how freely. Where the sensors leave the body open, many poses fit the
measurements; the poser's answer is their mean (the mean start, ``poser.NOISE_MODES``).
Re-noising that answer to a middle diffusion level and denoising it once more
(``diffusion.redraw``) lands on another pose that fits the same measurements; how far
such draws fall from the answer, per segment, is the spread. A measured segment is held
to its measurement in every draw, so its spread is 0; a segment the sensors pin down
through the body's chain spreads little, and one nothing constrains spreads most.

Cost: one denoiser call per draw (no mirror averaging: the draws estimate a width, not
a pose). The draws of the last ``pool`` frames are pooled, so one draw per frame gives a
spread from ``pool`` draws (0.2 s) at a sixth of a frame's cost; ``draws`` > 1 batches several
per frame and ``every`` > 1 computes them on every n-th frame only, the spread held in
between. The defaults are what keeps the live loop's p99 inside its budget
(docs/confidence.md, "Cost").

The spread is in degrees (mean geodesic angle of the pooled draws from the answer, the
knee hinge applied to both) and, for the root, in metres: the draws' root height and
root step apart from the answer's, the step's difference kept up for one second (what
drift it would cause). It is a width, not an error: docs/confidence.md gives the factors
that turn it into 50 and 90 % bands and how well it ranks the real error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import N_SEGMENTS

# re-noise level of the draws: one of the shipped model's live levels (1000 / 400 / 0),
# which training weights (``TrainConfig.t_focus``); docs/confidence.md, "Level"
DRAW_LEVEL = 400
# how long a root step's difference is kept up to make a root spread in metres
ROOT_HORIZON_S = 1.0


# (coverage, floor, scale): the error lies within max(floor, scale * spread) that share of the
# time; fit on the training actors' HDM05 clips at 6, 3 and 2 sites, pooled
# (docs/confidence.md: `imucap evaluate --data ../shared/data/hdm05/bd --confidence --fit-bands`)
SEGMENT_BANDS: tuple[tuple[float, float, float], ...] = ((0.5, 0.465, 3.392), (0.9, 0.749, 9.235))
ROOT_BANDS: tuple[tuple[float, float, float], ...] = ((0.5, 0.0, 0.528), (0.9, 0.0, 12.295))


@dataclass(frozen=True)
class ConfidenceSettings:
    """draws: inpaintings per computed frame (one batch); every: compute on every n-th
    frame and hold the spread in between; pool: how many of the latest draws make one
    spread; level: the diffusion level the answer is re-noised to; seed: the draws'
    noise (a replay reproduces its spreads)."""

    draws: int = 1
    every: int = 1
    pool: int = 4
    level: int = DRAW_LEVEL
    seed: int = 0

    def __post_init__(self) -> None:
        if self.draws < 1 or self.every < 1 or self.pool < 1:
            raise ValueError(f"confidence needs draws, every and pool >= 1, not {self}")
        if not 0 < self.level <= 1000:
            raise ValueError(f"confidence level {self.level} outside 1..1000")


def confidence_settings(spec: ConfidenceSettings | bool | None) -> ConfidenceSettings | None:
    """None/False = off, True = the defaults, or the settings themselves."""
    if spec is None or spec is False:
        return None
    return ConfidenceSettings() if spec is True else spec


class SpreadPool:
    """The latest ``size`` draws' deviations from their answers: (24,) degrees and a root
    distance each; the spread is their mean."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.reset()

    def reset(self) -> None:
        self._seg = np.zeros((self.size, N_SEGMENTS))
        self._root = np.zeros(self.size)
        self._n = 0
        self._next = 0
        self.spread_deg: np.ndarray | None = None
        self.root_spread_m: float | None = None

    def add(self, seg_deg: np.ndarray, root_m: np.ndarray) -> None:
        """seg_deg (k, 24), root_m (k,): this frame's draws; updates the spread."""
        for s, r in zip(seg_deg, root_m):
            self._seg[self._next] = s
            self._root[self._next] = r
            self._next = (self._next + 1) % self.size
            self._n = min(self._n + 1, self.size)
        self.spread_deg = self._seg[: self._n].mean(axis=0)
        self.root_spread_m = float(self._root[: self._n].mean())


def segment_deviation_deg(R_draws: Tensor, R: Tensor) -> np.ndarray:
    """(k, 24) angle (deg) of each draw's segments (k, 24, 3, 3) from the answer's (24, 3, 3)."""
    return np.degrees(matrix_angle_between(R_draws.to(torch.float64), R.to(torch.float64).expand_as(R_draws)).numpy())


def root_deviation_m(pz_draws: Tensor, pz: Tensor, dp_draws: Tensor, dp: Tensor, fps: float) -> np.ndarray:
    """(k,) root distance (m) of each draw from the answer: height apart, and the step's
    difference kept up for ``ROOT_HORIZON_S``."""
    dz = (pz_draws.reshape(-1) - pz.reshape(())).to(torch.float64)
    dxy = (dp_draws - dp).to(torch.float64).norm(dim=-1) * (fps * ROOT_HORIZON_S)
    return torch.sqrt(dz * dz + dxy * dxy).numpy()


def band(spread: np.ndarray | float, coverage: float = 0.9, root: bool = False) -> np.ndarray:
    """The radius (deg, or m for the root) the error stays within ``coverage`` of the time
    for a spread (one of the fitted coverages: 0.5, 0.9)."""
    for c, floor, scale in ROOT_BANDS if root else SEGMENT_BANDS:
        if abs(c - coverage) < 1e-9:
            return np.maximum(floor, scale * np.asarray(spread, dtype=np.float64))
    raise ValueError(f"no band fitted for coverage {coverage}")


__all__ = ["ConfidenceSettings", "confidence_settings", "SpreadPool", "segment_deviation_deg", "root_deviation_m",
           "band", "DRAW_LEVEL", "ROOT_HORIZON_S", "SEGMENT_BANDS", "ROOT_BANDS"]
