"""Where training data comes from: the real motion (through the dataset builder), a cached
array file, a factory, or synthetic clips; and the feature statistics the networks are
normalised by."""

from __future__ import annotations

import importlib
import math
import os
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from inference.body.body import anthropometric_offsets
from inference.body.rotations import axis_angle_to_matrix, matrix_to_rot6d
from inference.body.skeleton import N_SEGMENTS
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT, WINDOW
from inference.signals.resample import FPS_MODEL
from inference.training.augment import horizontal_pairs
from inference.training.config import STD_FLOOR


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


def load_dataset(spec: dict | str, causal: bool = False) -> Dataset:
    """Build a dataset from a config entry.

    ``causal`` (TrainConfig.causal): accelerations through the low-latency mode's trailing
    filter. Motion specs and factories that take a ``causal`` keyword get it; a spec that
    says otherwise itself is an error, and so is a prebuilt dataset (npz, synthetic), whose
    filter cannot be told, under ``causal``.

    - ``{"motion": [path, ...], "cache_dir": optional}``: every motion file under those
      paths (relative ones are taken under ``data_root()``) through
      ``inference.dataset.build_dataset`` (cached under ``cache_root()``);
    - ``{"factory": "module:callable", "kwargs": {...}}`` calls that and uses the result;
    - ``{"npz": path}`` or a plain path string loads an ``ArrayDataset`` cache;
    - ``{"synthetic": {"clips": 8, "frames": 90, "seed": 0}}`` makes a synthetic one.
    """
    if isinstance(spec, str | os.PathLike):
        spec = {"npz": os.fspath(spec)}
    said = spec.get("causal", (spec.get("kwargs") or {}).get("causal"))
    if said is not None and bool(said) != bool(causal):
        raise ValueError(f"dataset spec says causal={said} but the training config says causal={causal}: "
                         f"set TrainConfig.causal, the data follows it")
    if "motion" in spec:
        from inference.training.dataset import build_dataset

        paths = [p if Path(p).is_absolute() else data_root() / p for p in spec["motion"]]
        return build_dataset(paths, spec.get("cache_dir") or cache_root(),
                             progress=bool(spec.get("progress", True)), causal=causal)
    if "factory" in spec:
        mod_name, _, attr = spec["factory"].partition(":")
        obj: Any = importlib.import_module(mod_name)
        for part in attr.split("."):
            obj = getattr(obj, part)
        kwargs = dict(spec.get("kwargs", {}))
        if causal:
            kwargs["causal"] = True  # a factory without the keyword fails here, loudly
        return obj(**kwargs)
    if causal:
        raise ValueError(f"causal training needs motion files or a factory that filters them, not {spec!r}")
    if "npz" in spec:
        return ArrayDataset.load_npz(spec["npz"])
    if "synthetic" in spec:
        return synthetic_dataset(**spec["synthetic"])
    raise ValueError(f"cannot build a dataset from {spec!r} (need motion, factory, npz or synthetic)")


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
        for i, j in horizontal_pairs():
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
