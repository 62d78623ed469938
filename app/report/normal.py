"""The comparison band the report draws behind a patient's joint angles: mean +- SD over the gait cycle
of the walking strides of adult motion capture trials (``normal_band.json``, how it was made and its
sources' licenses in ``NORMAL_BAND.md`` beside it).

It is a reference from the motion capture this project trains on, built by the same events and angle
definitions as the report itself; it is NOT clinical normative data (no screened population, no
gait-lab marker protocol, few subjects, animation-studio actors among them), and the report says so
under every plot that shows it.

``band_from_motions`` builds it: every motion's truth, its events from the heel and toe points' speed
(``events.truth_contact_values``), its strides classified as the report classifies them; a trial counts
when it has at least ``MIN_STRIDES`` walking strides, all of them straight, and walking strides are
most of its strides; each kept stride's curves go in, and the band is the mean and SD over the trials'
own mean curves (so a long trial does not outweigh a short one).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .analysis import analyse
from .events import truth_contact_values

BAND_FILE = Path(__file__).with_name("normal_band.json")
MIN_STRIDES = 1  # walking strides of each foot at least (CMU's takes are 2-3 s: one or two strides a foot)
MIN_WALKING_SHARE = 0.6  # of a trial's strides (both feet) classified walking
SPEED_MPS = (0.8, 1.8)  # an ordinary adult walk (a trial's mean walking speed)
FPS = 60.0


@dataclass(frozen=True)
class NormalBand:
    """angle -> (mean (101,), sd (101,)), with what it was made of."""

    curves: dict[str, tuple[np.ndarray, np.ndarray]]
    trials: int
    strides: int
    sources: dict[str, int]  # dataset -> trials
    note: str

    def get(self, angle: str) -> tuple[np.ndarray, np.ndarray] | None:
        return self.curves.get(angle)


def load_band(path: str | Path = BAND_FILE) -> NormalBand | None:
    p = Path(path)
    if not p.exists():
        return None
    d = json.loads(p.read_text())
    curves = {a: (np.asarray(v["mean"], dtype=np.float64), np.asarray(v["sd"], dtype=np.float64))
              for a, v in d["angles"].items()}
    return NormalBand(curves, int(d["trials"]), int(d["strides"]), dict(d["sources"]), d["note"])


def dataset_of(name: str) -> str:
    n = name.lower()
    if n.startswith("dataset-"):
        return "bandai"
    if n.startswith("hdm_"):
        return "hdm05"
    return "cmu"


def trial_curves(motion) -> tuple[dict[str, np.ndarray], int, dict[str, Any]] | None:
    """A motion's per-angle mean curve over its walking strides (both sides pooled, each side's own
    angles), the number of strides, and why it was kept or not (``info``); None when it is no walk."""
    m = motion.resample(FPS)
    t = m.times
    values = truth_contact_values(m.contacts(), FPS)
    an = analyse(t, m.rot, m.root, t, values, "truth", threshold=0.0)
    s = an.summary
    walking = s.walking()
    n_all = len(s.strides)
    speed = float(np.mean([w.speed_mps for w in walking])) if walking else 0.0
    info = {"name": motion.name, "strides": n_all, "walking": len(walking), "speed_mps": round(speed, 2)}
    if (min(s.count("l"), s.count("r")) < MIN_STRIDES or len(walking) < MIN_WALKING_SHARE * n_all
            or not SPEED_MPS[0] <= speed <= SPEED_MPS[1]):
        return None
    curves = {}
    for a in an.cycles["l"]:
        both = np.concatenate([an.cycles["l"][a], an.cycles["r"][a]])
        curves[a] = both.mean(axis=0)
    return curves, len(walking), info


def band_from_motions(motions, note: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(the band as ``normal_band.json`` holds it, one line per kept trial); ``motions``: an iterable
    of ``Motion``."""
    per_trial: list[dict[str, np.ndarray]] = []
    kept: list[dict[str, Any]] = []
    strides = 0
    sources: dict[str, int] = {}
    for m in motions:
        got = trial_curves(m)
        if got is None:
            continue
        curves, n, info = got
        per_trial.append(curves)
        kept.append(info)
        strides += n
        ds = dataset_of(m.name)
        sources[ds] = sources.get(ds, 0) + 1
    if not per_trial:
        raise ValueError("no walking trial among the motions")
    angles = {}
    for a in per_trial[0]:
        stack = np.stack([c[a] for c in per_trial])
        angles[a] = {"mean": np.round(stack.mean(axis=0), 3).tolist(),
                     "sd": np.round(stack.std(axis=0, ddof=1) if len(stack) > 1 else np.zeros(stack.shape[1]),
                                    3).tolist()}
    band = {"note": note, "trials": len(per_trial), "strides": strides, "sources": sources,
            "pct": list(range(101)), "angles": angles}
    return band, kept
