"""Training data: feature clips from motion files, normalisation statistics, the paper's
kinetic-energy clip sampling and 61-frame windows, cached on disk.

A dataset is a list of unnormalised (T_i, 190) float32 clips at 20 Hz plus per-clip body
geometry (height, bone offsets, heel/toe offsets: the training losses run FK and need
them) and sampling weights. ``build_dataset`` turns motion files into one, and stores it
as one .npz named by a hash of the inputs (paths, sizes, mtimes) and of ``CODE_VERSION``,
so an unchanged rebuild is a file read. Bump ``CODE_VERSION`` whenever synthesis or the
feature layout changes meaning.

Sampling (paper sec. 3.3): clip i is drawn with probability proportional to its mean
linear kinetic energy (sum over segments of 0.5 m v_com^2, see inference.synthesis),
floored at 5% of the median so still clips (T-pose holds, standing) are still seen; then
a window start uniformly. A clip shorter than the window is padded at the front with its
first frame (dp = 0), matching the live poser, which starts from a standing history.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from inference.body.motion import Motion
from inference.features.codec import decode_features, features_from_kinematics, features_from_motion, motion_to_features
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT, WINDOW
from inference.signals.synthesis import kinetic_energy

log = logging.getLogger(__name__)

CODE_VERSION = "features-v4"  # bump when the meaning of cached features changes (loaders included)
WEIGHT_FLOOR_OF_MEDIAN = 0.05

# --------------------------------------------------------------------------- normaliser
# std floors per feature group: a feature that barely varies in the data must not be
# blown up into noise by a tiny std
_STD_FLOOR = {"acc": 0.1, "dp": 0.005, "pz": 0.02}


@dataclass
class Normalizer:
    """Per-feature affine normalisation x_n = (x - mean) / std, for numpy and torch.

    6D orientations (already in [-1, 1]) and contacts (0/1, and the inpainting mask copies
    them verbatim) are left as they are: mean 0, std 1. Accelerations, dp and root height
    get data statistics with a floored std."""

    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        self.mean = np.asarray(self.mean, dtype=np.float64).reshape(N_FEATURES)
        self.std = np.asarray(self.std, dtype=np.float64).reshape(N_FEATURES)
        if np.any(self.std <= 0) or not np.all(np.isfinite(self.mean)):
            raise ValueError("normaliser std must be positive and mean finite")

    @classmethod
    def identity(cls) -> Normalizer:
        return cls(np.zeros(N_FEATURES), np.ones(N_FEATURES))

    @classmethod
    def fit(cls, clips: Sequence[np.ndarray]) -> Normalizer:
        x = np.concatenate([np.asarray(c, dtype=np.float64) for c in clips], axis=0)
        mean = x.mean(0)
        std = x.std(0)
        for name, sl in (("acc", SL_ACC), ("dp", SL_DP), ("pz", SL_PZ)):
            std[sl] = np.maximum(std[sl], _STD_FLOOR[name])
        for sl in (SL_ROT, SL_CONTACT):
            mean[sl] = 0.0
            std[sl] = 1.0
        return cls(mean, std)

    def _params(self, x: Any) -> tuple[Any, Any]:
        if isinstance(x, np.ndarray):
            return self.mean.astype(x.dtype, copy=False), self.std.astype(x.dtype, copy=False)
        import torch

        if isinstance(x, torch.Tensor):
            kw = {"dtype": x.dtype, "device": x.device}
            return torch.as_tensor(self.mean, **kw), torch.as_tensor(self.std, **kw)
        return self.mean, self.std

    def normalize(self, x: Any) -> Any:
        m, s = self._params(x)
        return (x - m) / s

    def denormalize(self, x: Any) -> Any:
        m, s = self._params(x)
        return x * s + m

    def to_dict(self) -> dict[str, list[float]]:
        return {"mean": self.mean.tolist(), "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Normalizer:
        return cls(np.asarray(d["mean"]), np.asarray(d["std"]))

    def save(self, path: str | Path) -> None:
        """JSON (readable, 190 + 190 numbers; float repr round-trips exactly)."""
        Path(path).write_text(json.dumps(self.to_dict()))

    @classmethod
    def load(cls, path: str | Path) -> Normalizer:
        return cls.from_dict(json.loads(Path(path).read_text()))


# --------------------------------------------------------------------------- dataset
def clip_weights(mean_energy: np.ndarray, lengths: np.ndarray | None = None) -> np.ndarray:
    """Sampling probabilities from per-clip mean kinetic energies (module docstring).

    ``lengths`` (frames per clip) weighs each clip by its length too, so that every window
    end is drawn in proportion to its clip's energy: per-trial weights alone give a short
    clip the draws of a long one, which in our data hands HDM05's short hop clips 24% of
    all draws (0.8% of the frames) and its long floor clips 0.7% (3% of the frames)."""
    e = np.asarray(mean_energy, dtype=np.float64)
    if e.size == 0:
        return e
    floor = max(WEIGHT_FLOOR_OF_MEDIAN * float(np.median(e)), 1e-6)
    w = np.maximum(e, floor)
    if lengths is not None:
        w = w * np.asarray(lengths, dtype=np.float64)
    return w / w.sum()


@dataclass
class FeatureDataset:
    """Unnormalised 20 Hz feature clips with their bodies and sampling weights.

    clips: list of (T_i, 190) float32; heights (n,); offsets (n, 24, 3) Body.offsets;
    contact_offsets (n, 4, 3); energy (n,) mean kinetic energy (J); weights (n,) sampling
    probabilities (sum 1); names (n,) clip names (file paths)."""

    clips: list[np.ndarray]
    heights: np.ndarray
    offsets: np.ndarray
    contact_offsets: np.ndarray
    weights: np.ndarray
    names: list[str]
    energy: np.ndarray | None = None
    skipped: list[str] = field(default_factory=list)
    key: str = ""

    def __len__(self) -> int:
        return len(self.clips)

    @property
    def n_frames(self) -> int:
        return int(sum(c.shape[0] for c in self.clips))

    @classmethod
    def from_motions(cls, motions: Iterable[Motion], names: Sequence[str] | None = None) -> FeatureDataset:
        clips, h, off, coff, en, nm = [], [], [], [], [], []
        for i, m in enumerate(motions):
            clips.append(features_from_motion(m))
            h.append(m.body.height)
            off.append(m.body.offsets)
            coff.append(m.body.contact_offsets)
            en.append(float(kinetic_energy(m).mean()))
            nm.append(names[i] if names is not None else (m.name or f"clip{i}"))
        return cls._assemble(clips, h, off, coff, en, nm)

    @classmethod
    def _assemble(cls, clips, h, off, coff, en, nm, skipped=(), key="") -> FeatureDataset:
        en = np.asarray(en, dtype=np.float64)
        return cls(
            clips=[np.asarray(c, dtype=np.float32) for c in clips],
            heights=np.asarray(h, dtype=np.float64).reshape(-1),
            offsets=np.asarray(off, dtype=np.float64).reshape(-1, 24, 3),
            contact_offsets=np.asarray(coff, dtype=np.float64).reshape(-1, 4, 3),
            weights=clip_weights(en), names=list(nm), energy=en, skipped=list(skipped), key=key,
        )

    @classmethod
    def concat(cls, parts: Sequence[FeatureDataset]) -> FeatureDataset:
        """One dataset of every clip of ``parts``; sampling weights are recomputed from the
        clips' kinetic energy (rebalance afterwards if the parts need shares)."""
        parts = [p for p in parts if p.clips]
        if not parts:
            raise ValueError("nothing to concatenate")
        if any(p.energy is None for p in parts):
            raise ValueError("every part needs its clips' kinetic energy to be concatenated")
        return cls._assemble(
            [c for p in parts for c in p.clips],
            np.concatenate([p.heights for p in parts]),
            np.concatenate([p.offsets for p in parts]),
            np.concatenate([p.contact_offsets for p in parts]),
            np.concatenate([p.energy for p in parts]),
            [n for p in parts for n in p.names],
            [s for p in parts for s in p.skipped],
            "+".join(p.key for p in parts),
        )

    def normalizer(self) -> Normalizer:
        return Normalizer.fit(self.clips)

    def window(self, i: int, start: int, window: int = WINDOW) -> np.ndarray:
        """Frames [start, start+window) of clip i; frames before the clip's start (start < 0,
        or a clip shorter than the window) are its first frame held still (dp = 0), the way
        a live session starts from a standing history."""
        c = self.clips[i]
        T = c.shape[0]
        start = min(start, T - window)  # never past the end (a short clip: all of it)
        if start >= 0:
            return c[start:start + window]
        pad = min(-start, window)
        first = c[:1].copy()
        first[:, SL_DP] = 0.0
        return np.concatenate([np.repeat(first, pad, 0), c[: window - pad]], axis=0)

    def sample(self, rng: np.random.Generator, batch: int, window: int = WINDOW) -> dict[str, np.ndarray]:
        """A training batch: x (B, window, 190) float32 unnormalised, height (B,),
        offsets (B, 24, 3), contact_offsets (B, 4, 3), and the clip index (B,).

        Each window *ends* at a uniformly drawn frame of its clip (front-padded with the
        standing first frame when that is less than a window in). Why: the live poser
        reconstructs the last frame of its window, so every frame of a clip has to be a
        possible last frame. Drawing windows that fit inside the clip instead made the last
        frame of a short clip (most HDM05 clips are 1-3 s) always its final, standing frame,
        and models trained that way never learned mid-squat or mid-kick last frames."""
        if not self.clips:
            raise ValueError("empty dataset")
        idx = rng.choice(len(self.clips), size=batch, p=self.weights)
        x = np.empty((batch, window, N_FEATURES), dtype=np.float32)
        for b, i in enumerate(idx):
            T = self.clips[i].shape[0]
            end = int(rng.integers(1, T + 1))  # exclusive end: the last frame is end - 1
            x[b] = self.window(int(i), end - window, window)
        return {
            "x": x, "height": self.heights[idx].astype(np.float32),
            "offsets": self.offsets[idx].astype(np.float32),
            "contact_offsets": self.contact_offsets[idx].astype(np.float32), "clip": idx,
        }

    def save(self, path: str | Path) -> None:
        """One .npz (written to a temporary name, then renamed, so a killed build never
        leaves a half cache that looks valid)."""
        path = Path(path)
        lengths = np.array([c.shape[0] for c in self.clips], dtype=np.int64)
        data = np.concatenate(self.clips, 0) if self.clips else np.zeros((0, N_FEATURES), np.float32)
        # per-process temporary name: two runs building the same cache at once must not
        # rename each other's file away (seen when training two models in parallel)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp.npz")
        np.savez(
            tmp, data=data, lengths=lengths, heights=self.heights, offsets=self.offsets,
            contact_offsets=self.contact_offsets,
            energy=self.energy if self.energy is not None else np.zeros(len(self.clips)),
            names=np.array(self.names, dtype=str), skipped=np.array(self.skipped, dtype=str),
            key=np.array(self.key), code_version=np.array(CODE_VERSION),
        )
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: str | Path) -> FeatureDataset:
        with np.load(path, allow_pickle=False) as z:
            lengths = z["lengths"]
            data = z["data"]
            bounds = np.concatenate([[0], np.cumsum(lengths)])
            clips = [data[bounds[i]:bounds[i + 1]] for i in range(len(lengths))]
            return cls._assemble(
                clips, z["heights"], z["offsets"], z["contact_offsets"], z["energy"],
                [str(s) for s in z["names"]], [str(s) for s in z["skipped"]], str(z["key"]),
            )


# --------------------------------------------------------------------------- builder
def content_key(files: Sequence[Path], variant: str = "") -> str:
    """Hash of the inputs: each file's resolved path, size and mtime, plus CODE_VERSION and
    ``variant`` (what the loader does beyond loading, e.g. a speed change)."""
    h = hashlib.sha256((CODE_VERSION + ("\0" + variant if variant else "")).encode())
    for f in sorted(Path(p).resolve() for p in files):
        st = f.stat()
        h.update(f"{f}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def cache_path(cache_dir: str | Path, key: str) -> Path:
    return Path(cache_dir) / f"dataset-{key[:20]}.npz"


def build_dataset(
    paths: Sequence[str | Path],
    cache_dir: str | Path,
    loader: Callable[[Path], Motion] | None = None,
    finder: Callable[[Sequence[str | Path]], list[Path]] | None = None,
    progress: bool = True,
    variant: str = "",
    causal: bool = False,
) -> FeatureDataset:
    """Feature dataset of every motion file under `paths`, cached under `cache_dir`.

    loader/finder default to ``inference.loaders.load_motion`` / ``find_motion_files``;
    a custom loader that changes the motions must name what it does in ``variant`` (it
    keys the cache).
    Files that fail to load are skipped with a warning and listed in ``skipped`` (one bad
    file must not cost a night's build); the cache is reused when its key matches.
    ``causal``: accelerations through the low-latency mode's trailing filter (cached apart)."""
    if loader is None or finder is None:
        from inference import loaders  # lazy: the loaders pull in parsers training does not need

        loader = loader or loaders.load_motion
        finder = finder or loaders.find_motion_files
    files = [Path(f) for f in finder(paths)]
    if not files:
        raise FileNotFoundError(f"no motion files found under {', '.join(map(str, paths))}")
    key = content_key(files, ",".join(v for v in (variant, "causal" if causal else "") if v))
    out = cache_path(cache_dir, key)
    if out.exists():
        try:
            ds = FeatureDataset.load(out)
            log.info("dataset cache hit: %s", out)
            return ds
        except Exception as exc:  # corrupt cache: rebuild rather than fail
            log.warning("ignoring unreadable cache %s: %s", out, exc)
    from tqdm import tqdm

    from inference.signals.synthesis import kinematics

    clips, h, off, coff, en, nm, skipped = [], [], [], [], [], [], []
    for f in tqdm(files, desc="building dataset", unit="file", disable=not progress):
        try:
            m = loader(f)
            kin = kinematics(m)
            x = features_from_kinematics(kin, causal)
        except (ValueError, OSError, KeyError) as exc:
            log.warning("skipping %s: %s", f, exc)
            skipped.append(f"{f}: {exc}")
            continue
        clips.append(x)
        h.append(m.body.height)
        off.append(m.body.offsets)
        coff.append(m.body.contact_offsets)
        en.append(float(kinetic_energy(m).mean()))
        nm.append(str(f))
    if not clips:
        raise ValueError(f"none of the {len(files)} motion files could be read: {skipped[:3]}")
    ds = FeatureDataset._assemble(clips, h, off, coff, en, nm, skipped, key)
    Path(cache_dir).mkdir(parents=True, exist_ok=True)
    ds.save(out)
    return ds


__all__ = [
    "CODE_VERSION", "Normalizer", "FeatureDataset", "build_dataset", "content_key", "cache_path",
    "clip_weights", "motion_to_features", "features_from_motion", "decode_features",
]
