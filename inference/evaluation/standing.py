"""Does a standing body stay standing? The reconstruction of a walk that ends in a stand.

A real session ends (and often pauses) with the subject standing still. With every
measured segment still, the reconstruction must settle on what the sensors imply within
about a second, not hold a pose the inpainting drifted into: on the real x-IMU3 log the
right thigh was held 16-17 deg bent through 4 s of standing (docs/real_signals.md, "A
standing body"). This scores that on synthesized clips, where the truth is known: each
motion is extended by ``Motion.held`` (stepping into an N-pose, then standing still),
reconstructed from the given sites as live, and each segment's error is taken over the
stand after ``settle_s``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from inference.body.motion import Motion
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SEGMENT_INDEX
from inference.evaluation.runner import clip_input, clip_seed, evaluation_noise, reconstruct_clip
from inference.signals.resample import FPS_MODEL

# the segments a stand is judged on: the legs the sparse sets leave out
STAND_SEGMENTS = ("l_thigh", "r_thigh", "l_shank", "r_shank", "pelvis")


@dataclass(frozen=True)
class StandResult:
    """One clip's stand: per segment the mean error (deg) over the stand after settling,
    and the error one second into the stand and at its end (how it settles)."""

    name: str
    deg: dict[str, float]
    at_1s: dict[str, float]
    at_end: dict[str, float]


def stand_errors(model, motions: Sequence[Motion], sites: Sequence[str], stand_s: float = 4.0,
                 settle_s: float = 1.0, step_s: float = 0.6, seed: int = 0,
                 segments: Sequence[str] = STAND_SEGMENTS) -> list[StandResult]:
    """Each motion followed by ``stand_s`` seconds of standing (entered over ``step_s``),
    reconstructed from ``sites`` with ``model``; errors over the stand from ``settle_s``
    on."""
    out = []
    for m in motions:
        held = m.held(0.0, stand_s, step_s)
        inp = clip_input(held, sites, noise=evaluation_noise(), seed=clip_seed(seed, m.name))
        rec = reconstruct_clip(model, inp, seed=seed)
        T = len(inp.rot)
        n_stand = int(round(stand_s * FPS_MODEL))
        start = T - n_stand
        err = np.degrees(matrix_angle_between(rec.rot, inp.rot))  # (T, 24)
        k1 = min(start + int(round(settle_s * FPS_MODEL)), T - 1)
        deg, at1, end = {}, {}, {}
        for s in segments:
            e = err[:, SEGMENT_INDEX[s]]
            deg[s] = round(float(e[k1:].mean()), 2)
            at1[s] = round(float(e[k1]), 2)
            end[s] = round(float(e[-5:].mean()), 2)
        out.append(StandResult(m.name, deg, at1, end))
    return out


def summary(results: Sequence[StandResult]) -> dict[str, float]:
    """Segment -> mean over clips of the settled stand's error (deg)."""
    if not results:
        return {}
    return {s: round(float(np.mean([r.deg[s] for r in results])), 2) for s in results[0].deg}


__all__ = ["STAND_SEGMENTS", "StandResult", "stand_errors", "summary"]
