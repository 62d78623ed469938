"""The data split the shipped model is trained and validated on.

Issue 3 asks for Bandai + HDM05 actors bd, bk for training and actor dg for validation.
HDM05 clips are all shorter than 10 s, so root drift at 10 s (RE10) cannot be measured on
dg; we therefore also hold out one Bandai style, "sad" (dataset 1), whose walks run 11-16 s,
as a second validation set for the root-error figures. Everything else is trained on.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from inference.loaders import find_motion_files
from inference.metrics.plausibility import implausible_feature_frames, repair_feet
from inference.training.data import cache_root, data_root
from inference.training.dataset import FeatureDataset, build_dataset, clip_weights

HELD_OUT_BANDAI_STYLE = "_sad_"
# Bandai is 97% of the frames but covers only locomotion and gestures; HDM05 brings the
# squats, hops, kicks, throws and floor work. Sampling each source half of the time keeps
# the rarer HDM05 classes from drowning (kinetic-energy weights still apply within a source).
HDM05_SHARE = 0.5


def train_files(root: Path | None = None) -> list[Path]:
    root = root or data_root()
    bandai = [f for f in find_motion_files(root / "bandai") if HELD_OUT_BANDAI_STYLE not in f.name]
    return bandai + find_motion_files([root / "hdm05" / "bd", root / "hdm05" / "bk"])


def val_files(root: Path | None = None) -> list[Path]:
    """HDM05 actor dg: unseen person, motion classes seen in training."""
    return find_motion_files((root or data_root()) / "hdm05" / "dg")


def root_val_files(root: Path | None = None) -> list[Path]:
    """Held-out Bandai style: long enough clips for RE2/5/10."""
    return [f for f in find_motion_files((root or data_root()) / "bandai" / "d1") if HELD_OUT_BANDAI_STYLE in f.name]


def _build(files: list[Path], progress: bool = True, speed: float = 1.0, repair: bool = False) -> FeatureDataset:
    """The cached feature dataset of ``files``, performed at ``speed`` (copies at another
    speed get their own cache and names ``<file>@x<speed>``, so a clip and its copies stay apart),
    with broken feet repaired (``plausibility.repair_feet``) when ``repair``."""
    loader = None
    if speed != 1.0 or repair:
        from inference.loaders import load_motion

        def loader(f: Path):
            m = load_motion(f)
            if repair:
                m = repair_feet(m)[0]
            return m.at_speed(speed) if speed != 1.0 else m

    variant = ",".join(v for v in ("" if speed == 1.0 else f"speed={speed:g}", "repair_feet" if repair else "") if v)
    ds = build_dataset(files, cache_root(), loader=loader, finder=lambda paths: [Path(p) for p in paths],
                       progress=progress, variant=variant)
    if speed != 1.0:
        ds.names = [f"{n}@x{speed:g}" for n in ds.names]
    return ds


def build_files(paths, progress: bool = True) -> FeatureDataset:
    """Feature dataset (cached) of every motion file under ``paths``."""
    return _build(find_motion_files([Path(p) for p in paths]), progress)


def _is_hdm05(name: str) -> bool:
    return "hdm05" in name.lower() or Path(name).name.startswith("HDM_")


def balance_sources(ds: FeatureDataset, hdm05_share: float = HDM05_SHARE) -> FeatureDataset:
    """Rescale the clip sampling probabilities so HDM05 clips get `hdm05_share` of the draws."""
    is_hdm = np.array([_is_hdm05(str(n)) for n in ds.names])
    if is_hdm.all() or not is_hdm.any():
        return ds
    w = ds.weights.astype(np.float64).copy()
    w[is_hdm] *= hdm05_share / w[is_hdm].sum()
    w[~is_hdm] *= (1.0 - hdm05_share) / w[~is_hdm].sum()
    ds.weights = w / w.sum()
    return ds


def drop_implausible_clips(ds: FeatureDataset) -> list[str]:
    """Never draw a clip with a frame no body makes (``plausibility``): its sampling weight
    becomes 0. Whole clips, not frames, because a window is 3 s of one clip and cutting
    frames out of it would join motions that never met. Returns the dropped clips' names."""
    dropped = []
    w = ds.weights.astype(np.float64).copy()
    for i, clip in enumerate(ds.clips):
        if implausible_feature_frames(clip).any():
            w[i] = 0.0
            dropped.append(str(ds.names[i]))
    if w.sum() <= 0:
        raise ValueError("every clip holds an implausible frame; nothing left to train on")
    ds.weights = w / w.sum()
    return dropped


def train_set(
    progress: bool = True, hdm05_share: float = HDM05_SHARE, hdm05_speeds: Sequence[float] = (),
    energy_per: str = "trial", drop_implausible: bool = False, repair_implausible: bool = False,
) -> FeatureDataset:
    """The training split. ``hdm05_speeds``: extra copies of the HDM05 clips performed at
    these speed factors (``Motion.at_speed``), sharing the HDM05 half of the draws. Two
    HDM05 actors are all the training data has of squats, kicks and throws, so their tempo
    could be learnt as part of the movement. Against the unseen actor, with the mean start,
    the copies beat a control run by 0.5-0.7 deg with only the shanks worn (docs/model.md,
    "Augmentation"); the shipped model is trained with 0.8, 0.9, 1.1 and 1.25
    (configs/shipped_diffusion.json).
    Bandai (many actors and styles) is left at its own speed.

    ``energy_per``: "trial" draws clips by their mean kinetic energy (the paper's words,
    sec. 3.3); "window" also weighs each clip by its length, so each window is drawn by its
    clip's energy whatever the clip's length (``dataset.clip_weights``). The shipped
    diffusion model is trained with "window" from its first step.

    ``drop_implausible``: clips with a frame no body makes are never drawn
    (``drop_implausible_clips``); their names go to stderr when ``progress``.
    ``repair_implausible``: every clip is loaded through ``plausibility.repair_feet``, so a
    clip keeps its squat or kick and loses only the solver's broken foot."""
    if energy_per not in ("trial", "window"):
        raise ValueError(f"energy_per must be 'trial' or 'window', not {energy_per!r}")
    files = train_files()
    base = _build(files, progress, repair=repair_implausible)
    if hdm05_speeds:
        hdm = [f for f in files if _is_hdm05(str(f))]
        base = FeatureDataset.concat([base, *(_build(hdm, progress, float(s), repair_implausible)
                                              for s in hdm05_speeds)])
    if energy_per == "window":
        base.weights = clip_weights(base.energy, [len(c) for c in base.clips])
    if drop_implausible:
        dropped = drop_implausible_clips(base)
        if progress:
            print(f"train_set: {len(dropped)} clip(s) with implausible frames never drawn: {', '.join(dropped)}",
                  file=sys.stderr)
    return balance_sources(base, hdm05_share)


def val_set(progress: bool = True) -> FeatureDataset:
    return _build(val_files(), progress)
