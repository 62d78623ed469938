"""Which model and helper-net files the poser runs, and the defaults a model file carries
(steps, inpainting noise, mirror averaging): resolved here, below the poser, so the
evaluation, the CLI and the sessions name a model the same way."""

from __future__ import annotations

import functools
import os
import types
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from inference.model.diffusion import paper_steps, parse_steps
from inference.model.files import LoadedModel, load_model
from inference.poser.contact_detector import ContactDetector, load_detector
from inference.poser.pelvis_odometry import Odometry, load_odometry

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"


DEFAULT_WEIGHTS: dict[str, Path] = {
    "diffusion": WEIGHTS_DIR / "diffusionposer.pt",
    "regressor": WEIGHTS_DIR / "regressor.pt",
    # the default's network over its newest 21 frames without mirror averaging: the same three-level
    # chain at about a third of its compute per pose, for a laptop the default does not keep up on;
    # it costs a little accuracy (MODEL_CARD.md)
    "fast": WEIGHTS_DIR / "diffusionposer_fast.pt",
}


CONTACT_DETECTOR_WEIGHTS = WEIGHTS_DIR / "contact_detector.pt"


PELVIS_ODOMETRY_WEIGHTS = WEIGHTS_DIR / "pelvis_odometry.pt"


POSER_KINDS = ("diffusion", "regressor", "floor")


# the live default: the shipped file that serves the worn sensors best at about a third of the
# full model's compute (``model_for_sites``)
AUTO = "auto"


# what ``--model`` takes besides a file: the shipped files by name, the live default, and the floor
MODEL_NAMES = (*DEFAULT_WEIGHTS, AUTO, "floor")


# a leg whose thigh is worn and whose shank is not: there the 21-frame file answers the shank and
# foot below the worn thigh worse than the full model (the OpenSense walk's feet with pelvis +
# thighs +0.8-0.9 deg, settled; dg +0.54 unsettled; docs/model.md, "The live default")
_THIGH_WITHOUT_SHANK = (("l_thigh", "l_shank"), ("r_thigh", "r_shank"))


def model_for_sites(spec: str | os.PathLike | LoadedModel | None,
                    sites: Sequence[str] | None = None) -> str | os.PathLike | LoadedModel | None:
    """The shipped name ``spec`` stands for with ``sites`` worn: "auto" is "fast" (the 21-frame
    int8 file, a third of the compute) unless a worn thigh has no worn shank below it, where
    it is "diffusion" (the full model; the 21-frame window loses the feet there). Sites
    unknown (None): "fast". Any other spec is itself."""
    if not isinstance(spec, str) or spec != AUTO:
        return spec
    worn = set(sites or ())
    if any(t in worn and s not in worn for t, s in _THIGH_WITHOUT_SHANK):
        return "diffusion"
    return "fast"


# what of the history the model is told is known: all of it (the paper: measured and
# reconstructed features), or only what was measured (reconstructions are then just the
# starting guess, re-inferred every frame from 3 s of measurements)
HISTORY_MODES = ("reconstructed", "measured")


# inpainting noise: a fresh draw every frame (the paper), or the same draw every frame, which
# makes the output a deterministic function of the window, so it only moves when the
# measurements do (much less jitter at the same accuracy; docs/model.md, "Inference"), or no draw
# at all: the first level starts from the prior's mean (``inpaint(start="mean")``), which
# estimates the mean pose given the measurements instead of sampling one (docs/model.md,
# "Inference": the largest gain where few sensors leave the pose open)
NOISE_MODES = ("fresh", "fixed", "mean")


# a predicted contact value above this puts the foot point on the ground for the root
# correction. A model unsure of a contact predicts something in between, and a swinging foot
# taken as planted cancels the step; how sure a model is depends on the model, so the model
# file may carry its own (meta "contact_threshold", `imucap train --export --contact-threshold`).
# The shipped diffusion model carries 0.3 (docs/model.md, "Root and contacts": swept where the shank contact
# detector does not apply); this is the default otherwise.
CONTACT_THRESHOLD = 0.5


def default_weights(kind: str = "diffusion") -> Path:
    """Path of the shipped weights of `kind`; a clear error (with the command that makes
    them) when they are not there, because a half-installed checkout should say so
    rather than fall back to something silently worse."""
    if kind not in DEFAULT_WEIGHTS:
        raise ValueError(f"no shipped weights named {kind!r}; names: {', '.join(DEFAULT_WEIGHTS)}")
    path = DEFAULT_WEIGHTS[kind]
    if not path.exists():
        raise FileNotFoundError(
            f"the default {kind} model {path} is missing. Train one with "
            f"`imucap train --config CONFIG.json --out runs/{kind}` (config field \"kind\": \"{kind}\", "
            f"see inference/training/loop.py TrainConfig) and copy runs/{kind}/model.pt to {path}, "
            f"or pass --model PATH.pt"
        )
    return path


def resolve_detector(spec: ContactDetector | str | os.PathLike | None) -> ContactDetector | None:
    """"default" = the shipped detector if it is installed (else the model's own contacts,
    with a warning), None = none, a path = that file."""
    return _resolve_stage(spec, ContactDetector, CONTACT_DETECTOR_WEIGHTS, load_detector,
                          "root correction uses the model's contacts (train one with "
                          "`imucap train --contact-detector --out DIR`)")


def resolve_odometry(spec: Odometry | str | os.PathLike | None) -> Odometry | None:
    """"default" = the shipped pelvis odometry if it is installed (else the model's own
    root displacement, with a warning), None = none, a path = that file."""
    return _resolve_stage(spec, Odometry, PELVIS_ODOMETRY_WEIGHTS, load_odometry,
                          "without both shanks the root follows the model's own displacement (train one with "
                          "`imucap train --pelvis-odometry --out DIR`)")


def _resolve_stage(spec, cls: type | types.UnionType, path: Path, loader, missing: str):
    """A helper stage of the poser (contact detector, pelvis odometry) from its spec."""
    if spec is None or isinstance(spec, cls):
        return spec
    if os.fspath(spec) == "default":
        if not path.exists():
            warnings.warn(f"{path} is missing: {missing}", stacklevel=4)
            return None
        return _shipped_stage(path, path.stat().st_mtime_ns, loader)
    return loader(spec)


@functools.lru_cache(maxsize=4)
def _shipped_stage(path: Path, mtime_ns: int, loader):
    """One shared instance per shipped file (the stages hold no state between calls);
    reloaded if the file changes."""
    return loader(path)


def resolve_model(spec: str | os.PathLike | LoadedModel | None = "diffusion",
                  window: int | None = None) -> LoadedModel | None:
    """A model from a CLI-style spec: "diffusion"/"regressor"/"fast" (shipped weights), "auto"
    (the live default with no sites known: "fast"; ``model_for_sites`` chooses by the sites), "floor"
    (no model: returns None), a path to a model file or checkpoint, or a LoadedModel;
    ``window``: the frames it reads (``inference.model.files.with_window``; None: its file's)."""
    if spec is None or isinstance(spec, LoadedModel):
        return spec
    s = os.fspath(spec)
    if s == "floor":
        return None
    s = os.fspath(model_for_sites(s))
    if s in DEFAULT_WEIGHTS:
        return load_model(default_weights(s), window=window)
    if not Path(s).exists():
        raise FileNotFoundError(f"model {s!r}: not a file, and not one of {', '.join(MODEL_NAMES)}")
    return load_model(s, window=window)


def draws_model(model: LoadedModel | None) -> LoadedModel | None:
    """The model whose calls make a poser's confidence draws: ``model`` itself, or the one its
    file names (meta ``draws_from``: a shipped name or a file). A chain student learns only the
    states its own chain reaches, not an answer re-noised to a middle level, so its file names
    its teacher; the two must read the same features."""
    spec = ((model.meta or {}) if model is not None else {}).get("draws_from")
    if not spec:
        return model
    path = DEFAULT_WEIGHTS[spec] if spec in DEFAULT_WEIGHTS else Path(spec)
    if not path.exists():
        raise FileNotFoundError(f"the confidence draws of this model come from {spec!r}, which is missing ({path})")
    other = _draws_file(path.resolve(), path.stat().st_mtime_ns, model.config.window)
    same = (np.array_equal(np.asarray(other.norm_mean), np.asarray(model.norm_mean))
            and np.array_equal(np.asarray(other.norm_std), np.asarray(model.norm_std)))
    if other.kind != "diffusion" or not same or other.config.mask_input != model.config.mask_input:
        raise ValueError(f"draws_from {spec!r}: not a diffusion model reading this model's features")
    return other


@functools.lru_cache(maxsize=2)
def _draws_file(path: Path, mtime_ns: int, window: int) -> LoadedModel:
    """One loaded draws model per file (the posers of an offline run share its traces)."""
    return load_model(path, window=window)


def default_steps(model: LoadedModel | None) -> list[int]:
    """The step list a model runs with unless told otherwise: the one recorded in its
    file (``meta["default_steps"]``, written by whoever tuned speed vs accuracy for the
    shipped weights), else the paper's 10D list."""
    meta = (model.meta or {}) if model is not None else {}
    if meta.get("default_steps") is not None:
        return parse_steps(meta["default_steps"])
    return paper_steps()


def noise_mode_for(model: LoadedModel | None, noise: str | None = None) -> str:
    """The inpainting noise mode a poser runs with: ``noise`` if given, else what the model
    file recommends (meta, set at export), else the paper's fresh draws."""
    meta = (model.meta or {}) if model is not None else {}
    return noise or meta.get("noise") or "fresh"


def mirror_for(model: LoadedModel | None, mirror: bool | None = None) -> bool:
    """Whether a poser mirror-averages (``mirror.MirrorAveraged``): ``mirror`` if given, else
    what the model file says; never for the floor, which has no model to ask."""
    if model is None:
        return False
    return bool((model.meta or {}).get("mirror", False) if mirror is None else mirror)
