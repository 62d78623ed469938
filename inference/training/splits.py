"""The data split the shipped model is trained and validated on.

Training: Bandai (every style but one) and HDM05 actors bd and bk, and, with
``cmu_share``, the CMU subjects not held out. Validation, by person: HDM05 actor dg, and
the CMU subjects in ``CMU_VAL_SUBJECTS``. HDM05 clips are all shorter than 10 s, so root
drift at 10 s (RE10) cannot be measured on dg; one Bandai style, "sad" (dataset 1), whose
walks run 11-16 s, is also held out for the root-error figures.
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


# CMU subjects kept for validation: 02 (CMU's own ASF/AMC, its own proportions; walks, a
# jump, crouches, five takes over 10 s for root drift), 06 (the iClone layout, clean takes,
# with its duplicate Daz take on the same side) and 08 (walks in the Daz layout): 3.5 of
# 16.4 min. Not 01 (46 % of the minutes, mostly climbing), 05 (its knee flips), 03 (uneven
# terrain confounds floor-based metrics) or the tiny ones.
CMU_VAL_SUBJECTS: tuple[str, ...] = ("02", "06", "08")
# takes never trained on: 09_10 tumbles at 50-90 rad/s in half its frames (corrupt); in
# these iClone takes of subject 05 a knee jumps ~30 cm sideways for 7-28 frames
CMU_EXCLUDED = ("09_10", "005_05", "005_06", "005_08", "005_16", "005_17", "005_18", "005_19")
# draw shares per source when CMU is trained on
SHARES_WITH_CMU = {"bandai": 0.3, "hdm05": 0.35, "cmu": 0.35}
# the CMU caches' own key: bump when the CMU layouts' rest-pose turns change (joint_maps.py),
# which CODE_VERSION would bump for every source
CMU_CACHE_TAG = "rest-turns-1"


def cmu_subject(path: Path | str) -> str:
    """The CMU subject of a file in any of the three layouts, two digits: ``asf_amc/07/07_01.amc``,
    ``bvh_cgspeed/07_01.bvh.gz`` and ``bvh_iclone/007_01.bvh`` are all subject 07."""
    stem = Path(path).name.split(".")[0]
    return f"{int(stem.split('_')[0]):02d}"


def cmu_files(root: Path | None = None, subjects: Sequence[str] | None = None,
              exclude: Sequence[str] = ()) -> list[Path]:
    files = [f for f in find_motion_files((root or data_root()) / "cmu")
             if f.suffix.lower() != ".asf" and f.name.split(".")[0] not in CMU_EXCLUDED]
    return [f for f in files if (subjects is None or cmu_subject(f) in subjects) and cmu_subject(f) not in exclude]


def train_files(root: Path | None = None) -> list[Path]:
    root = root or data_root()
    bandai = [f for f in find_motion_files(root / "bandai") if HELD_OUT_BANDAI_STYLE not in f.name]
    return bandai + find_motion_files([root / "hdm05" / "bd", root / "hdm05" / "bk"])


def cmu_train_files(root: Path | None = None) -> list[Path]:
    return cmu_files(root, exclude=CMU_VAL_SUBJECTS)


def cmu_val_files(root: Path | None = None) -> list[Path]:
    return cmu_files(root, subjects=CMU_VAL_SUBJECTS)


def val_files(root: Path | None = None) -> list[Path]:
    """HDM05 actor dg: unseen person, motion classes seen in training."""
    return find_motion_files((root or data_root()) / "hdm05" / "dg")


def root_val_files(root: Path | None = None) -> list[Path]:
    """Held-out Bandai style: long enough clips for RE2/5/10."""
    return [f for f in find_motion_files((root or data_root()) / "bandai" / "d1") if HELD_OUT_BANDAI_STYLE in f.name]


# the held-out sets by name, for `imucap evaluate --data @NAME`: a report's reproduce line then
# names the set instead of listing its files, and no one has to remember which CMU takes it holds
HELD_OUT_SETS = {
    "dg": val_files,  # HDM05 actor dg: an unseen person
    "sad": root_val_files,  # Bandai dataset 1, style "sad": an unseen style, walks long enough for RE10
    "cmu-val": cmu_val_files,  # CMU subjects CMU_VAL_SUBJECTS: unseen people, studio and skeletons
}


def held_out_files(name: str, root: Path | None = None) -> list[Path]:
    """The motion files of a held-out set named in ``HELD_OUT_SETS`` (with or without its ``@``)."""
    key = name.removeprefix("@")
    if key not in HELD_OUT_SETS:
        raise ValueError(f"unknown held-out set @{key}; choose from "
                         f"{', '.join('@' + k for k in HELD_OUT_SETS)}")
    try:
        files = HELD_OUT_SETS[key](root)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"held-out set @{key}: {e}") from None
    if not files:
        raise FileNotFoundError(f"held-out set @{key}: no motion files under {root or data_root()}")
    return files


def _build(files: list[Path], progress: bool = True, speed: float = 1.0, repair: bool = False,
           causal: bool = False, tag: str = "", hold: float = 0.0, settle: float = 0.0,
           turn: float = 0.0) -> FeatureDataset:
    """The cached feature dataset of ``files``, performed at ``speed`` (copies at another
    speed get their own cache and names ``<file>@x<speed>``, so a clip and its copies stay apart),
    with broken feet repaired (``plausibility.repair_feet``) when ``repair``, accelerations
    through the low-latency mode's trailing filter when ``causal``, and the subject standing
    still ``hold`` seconds before and after the movement, stepping into and out of an N-pose
    over ``settle`` seconds when ``settle`` (``Motion.held``; names ``<file>@hold<s>``) when ``hold``, and
    the whole body turning about the vertical at ``turn`` deg/s (``Motion.turning``; names
    ``<file>@turn<rate>``) when ``turn``."""
    loader = None
    if speed != 1.0 or repair or hold or turn:
        from inference.loaders import load_motion

        def loader(f: Path):
            m = load_motion(f)
            if repair:
                m = repair_feet(m)[0]
            m = m.at_speed(speed) if speed != 1.0 else m
            m = m.turning(turn) if turn else m
            return m.held(hold, hold, settle) if hold else m

    variant = ",".join(v for v in ("" if speed == 1.0 else f"speed={speed:g}", "repair_feet" if repair else "", tag,
                                   f"hold={hold:g}" if hold else "", f"settle={settle:g}" if settle else "",
                                   f"turn={turn:g}" if turn else "") if v)
    ds = build_dataset(files, cache_root(), loader=loader, finder=lambda paths: [Path(p) for p in paths],
                       progress=progress, variant=variant, causal=causal)
    if speed != 1.0:
        ds.names = [f"{n}@x{speed:g}" for n in ds.names]
    if turn:
        ds.names = [f"{n}@turn{turn:g}" for n in ds.names]
    if hold:
        ds.names = [f"{n}@hold{hold:g}" for n in ds.names]
    return ds


def build_files(paths, progress: bool = True, causal: bool = False) -> FeatureDataset:
    """Feature dataset (cached) of every motion file under ``paths``."""
    return _build(find_motion_files([Path(p) for p in paths]), progress, causal=causal)


def is_walk(name: str | Path) -> bool:
    """Whether a Bandai clip is a walk of any kind (straight, back, sideways, turning)."""
    stem = Path(name).name
    return "_walk" in stem and not _is_hdm05(stem)


def is_variant(name: str | Path) -> bool:
    """Whether a clip name is one of ``train_set``'s real-motion copies (slowed walk, held stand,
    turning walk)."""
    return ("@hold" in str(name) or "@turn" in str(name)
            or ("@x" in str(name) and is_walk(str(name).split("@")[0])))


def _give_share(ds: FeatureDataset, part: np.ndarray, share: float) -> FeatureDataset:
    """Rescale the sampling probabilities so the clips in ``part`` get ``share`` of the draws,
    each side keeping its clips' proportions; nothing moves when one side is empty."""
    if part.all() or not part.any():
        return ds
    w = ds.weights.astype(np.float64).copy()
    w[part] *= share / w[part].sum()
    w[~part] *= (1.0 - share) / w[~part].sum()
    ds.weights = w / w.sum()
    return ds


def share_variants(ds: FeatureDataset, share: float) -> FeatureDataset:
    """Give the real-motion copies (``is_variant``) ``share`` of the draws, the rest keeping
    their proportions among themselves."""
    return _give_share(ds, np.array([is_variant(n) for n in ds.names]), share)


def _is_hdm05(name: str) -> bool:
    return "hdm05" in name.lower() or Path(name).name.startswith("HDM_")


def source_of(name: str) -> str:
    """Which dataset a clip name comes from: hdm05, cmu or bandai."""
    if _is_hdm05(name):
        return "hdm05"
    return "cmu" if "/cmu/" in str(name).replace("\\", "/") else "bandai"


def readings_of(names: Sequence[str]) -> np.ndarray:
    """(n,) index in ``READINGS`` of each clip's dataset: the reading token it trains."""
    from inference.model.config import READINGS

    return np.array([READINGS.index(source_of(str(n))) for n in names], dtype=np.int64)


def balance_shares(ds: FeatureDataset, shares: dict[str, float]) -> FeatureDataset:
    """Rescale the clip sampling probabilities so each source gets its share of the draws
    (sources absent from ``ds`` give theirs to the others, in proportion)."""
    src = np.array([source_of(str(n)) for n in ds.names])
    present = {k: v for k, v in shares.items() if (src == k).any()}
    total = sum(present.values())
    w = ds.weights.astype(np.float64).copy()
    for k, v in present.items():
        m = src == k
        w[m] *= (v / total) / w[m].sum()
    ds.weights = w / w.sum()
    return ds


def balance_sources(ds: FeatureDataset, hdm05_share: float = HDM05_SHARE) -> FeatureDataset:
    """Rescale the clip sampling probabilities so HDM05 clips get `hdm05_share` of the draws."""
    return _give_share(ds, np.array([_is_hdm05(str(n)) for n in ds.names]), hdm05_share)


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
    cmu: bool = False, causal: bool = False, cmu_shares: dict[str, float] | None = None,
    slow_walks: Sequence[float] = (), stand_hold: float = 0.0, variant_share: float = 0.25,
    turn_walks: Sequence[float] = (), turn_speed: float = 0.6,
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
    clip keeps its squat or kick and loses only the solver's broken foot.

    ``cmu``: also the CMU subjects not held out (``CMU_VAL_SUBJECTS``), as a source of
    their own (cached apart, so the Bandai and HDM05 caches stay valid); the draws are then
    shared ``SHARES_WITH_CMU`` between the three sources, or ``cmu_shares`` (source -> share).

    ``causal``: accelerations through the trailing filter of the low-latency mode (a model
    for ``--latency low``; TrainConfig.causal passes it).

    Motion like real sessions' (docs/real_signals.md): real logs hold slow short steps,
    turns on the spot and long stands after walking, which the brisk, tightly cut training
    clips hold little of. ``slow_walks``: copies of every Bandai walk (straight, back,
    sideways, turning) performed at these speed factors (< 1: slower); ``stand_hold``: copies
    of those walks and of the HDM05 clips with the subject standing still this many seconds
    before and after (the walks stepping into and out of an N-pose over 0.6 s, as they are cut
    mid-stride). ``turn_walks``: copies of every Bandai walk performed at ``turn_speed`` and
    turned about the vertical at each of these rates (deg/s, ``Motion.turning``): a slow walk
    turned at 90-180 deg/s steps round a circle of 0.3-0.6 m, the nearest the data comes to a
    turn on the spot. Together these copies take ``variant_share`` of the draws."""
    if energy_per not in ("trial", "window"):
        raise ValueError(f"energy_per must be 'trial' or 'window', not {energy_per!r}")
    files = train_files()
    base = _build(files, progress, repair=repair_implausible, causal=causal)
    if hdm05_speeds:
        hdm = [f for f in files if _is_hdm05(str(f))]
        base = FeatureDataset.concat([base, *(_build(hdm, progress, float(s), repair_implausible, causal)
                                              for s in hdm05_speeds)])
    if cmu:
        base = FeatureDataset.concat([base, _build(cmu_train_files(), progress, repair=repair_implausible,
                                                   causal=causal, tag=CMU_CACHE_TAG)])
    walks = [f for f in files if is_walk(f)]
    extras = [_build(walks, progress, float(s), repair_implausible, causal) for s in slow_walks]
    extras += [_build(walks, progress, float(turn_speed), repair_implausible, causal, turn=float(r))
               for r in turn_walks]
    if stand_hold:
        # walks are cut mid-stride: they step into and out of a stand; HDM05 clips start and end standing
        extras.append(_build(walks, progress, repair=repair_implausible, causal=causal, hold=float(stand_hold),
                             settle=0.6))
        extras.append(_build([f for f in files if _is_hdm05(str(f))], progress, repair=repair_implausible,
                             causal=causal, hold=float(stand_hold)))
    if extras:
        base = FeatureDataset.concat([base, *extras])
    if energy_per == "window":
        base.weights = clip_weights(base.energy, [len(c) for c in base.clips])
    if drop_implausible:
        dropped = drop_implausible_clips(base)
        if progress:
            print(f"train_set: {len(dropped)} clip(s) with implausible frames never drawn: {', '.join(dropped)}",
                  file=sys.stderr)
    base = (balance_shares(base, cmu_shares or SHARES_WITH_CMU) if cmu
            else balance_sources(base, hdm05_share))
    return share_variants(base, variant_share) if extras else base


def val_set(progress: bool = True, cmu: bool = False, causal: bool = False) -> FeatureDataset:
    """HDM05 actor dg (and with ``cmu`` the held-out CMU subjects too)."""
    if cmu:
        return FeatureDataset.concat([_build(val_files(), progress, causal=causal),
                                      _build(cmu_val_files(), progress, causal=causal, tag=CMU_CACHE_TAG)])
    return _build(val_files(), progress, causal=causal)
