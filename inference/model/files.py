"""Model files: build a fresh network of a kind, save and load inference files and
training checkpoints. Above the denoiser and the regressor, the one place that knows both."""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from inference.model.config import READINGS, ModelConfig, atomic_torch_save
from inference.model.denoiser import Denoiser
from inference.model.regressor import Regressor

MODEL_KINDS = ("diffusion", "regressor")


MODEL_FORMAT = "imucap-model-v1"


def build_model(kind: str, config: ModelConfig | None = None) -> nn.Module:
    """A fresh Denoiser ("diffusion") or Regressor ("regressor")."""
    if kind == "diffusion":
        return Denoiser(config)
    if kind == "regressor":
        return Regressor(config)
    raise ValueError(f"unknown model kind {kind!r}; choose one of {', '.join(MODEL_KINDS)}")


@dataclass
class LoadedModel:
    """A model ready for inference plus what it needs around it: the feature normaliser
    statistics (the network works on normalised features) and its provenance."""

    model: nn.Module
    kind: str
    config: ModelConfig
    norm_mean: np.ndarray  # (F,) float32
    norm_std: np.ndarray  # (F,) float32
    step: int = 0
    meta: dict | None = None

    def normalize(self, x: Tensor) -> Tensor:
        mean = torch.as_tensor(self.norm_mean, dtype=x.dtype)
        return (x - mean) / torch.as_tensor(self.norm_std, dtype=x.dtype)

    def denormalize(self, x: Tensor) -> Tensor:
        mean = torch.as_tensor(self.norm_mean, dtype=x.dtype)
        return x * torch.as_tensor(self.norm_std, dtype=x.dtype) + mean


def save_model(path: str | os.PathLike, model: nn.Module, kind: str, norm_mean: np.ndarray,
               norm_std: np.ndarray, step: int = 0, meta: dict | None = None, fp16: bool = False) -> None:
    """Write an inference model file (weights only, no optimizer), atomically.

    ``fp16`` halves the file (shipping weights); they are cast back to float32 on load
    because CPU inference in half precision is slower, not faster.
    """
    sd = {k: (v.half() if fp16 and v.is_floating_point() else v).detach().cpu().clone()
          for k, v in model.state_dict().items()}
    obj = {
        "format": MODEL_FORMAT, "kind": kind, "model_config": model.config.to_dict(), "state_dict": sd,
        "norm_mean": np.asarray(norm_mean, np.float32), "norm_std": np.asarray(norm_std, np.float32),
        "step": int(step), "meta": meta or {},
    }
    atomic_torch_save(obj, path)


class ModelFileError(ValueError):
    """A model file that cannot be used; the message is one line naming the file."""

    def __init__(self, path: str | os.PathLike, problem: str) -> None:
        super().__init__(f"{os.fspath(path)}: {problem}")
        self.path = os.fspath(path)


def _first_line(exc: BaseException) -> str:
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    return (text.strip().splitlines() or [type(exc).__name__])[0][:200]


def _read_file(path: str | os.PathLike) -> Any:
    """torch.load, with a damaged file named as such: torch's own errors (a zip reader's
    internals, a pickle's memo) do not say which file or that it is damaged, and torch does
    not check the archive's CRCs, so a flipped block of weights would load as a model."""
    def unreadable(exc: BaseException) -> ModelFileError:
        return ModelFileError(path, f"not a readable model file (truncated or damaged: {_first_line(exc)})")

    if os.path.isfile(path) and os.path.getsize(path) == 0:
        raise ModelFileError(path, "an empty file, not a model (nothing was written to it)")
    if zipfile.is_zipfile(path):
        try:
            with zipfile.ZipFile(path) as z:
                bad = z.testzip()
        except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
            raise unreadable(exc) from None
        if bad is not None:
            raise ModelFileError(path, f"damaged model file (checksum of {bad} failed)")
    else:
        try:
            with open(path, "rb") as fh:
                zipped = fh.read(4) == b"PK\x03\x04"
        except OSError:
            zipped = False
        if zipped:  # a zip archive (torch's format) whose directory at the end is missing
            raise ModelFileError(path, "truncated model file (the end of its archive is missing)")
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except (FileNotFoundError, IsADirectoryError, PermissionError):
        raise
    except Exception as exc:  # noqa: BLE001 - unpickling a broken file fails in many ways
        raise unreadable(exc) from None


def _what(obj: Any) -> str:
    if isinstance(obj, dict):
        keys = ", ".join(sorted(map(str, obj))[:6])
        return f"a dict of {keys}" if keys else "an empty dict"
    return f"a {type(obj).__name__}"


def with_reading(cfg: ModelConfig, reading: str | None) -> ModelConfig:
    """``cfg`` answering in ``reading`` (a name in READINGS) when not told; None keeps it."""
    if reading is None:
        return cfg
    if reading not in READINGS:
        raise ValueError(f"unknown reading {reading!r}: one of {', '.join(READINGS)}")
    if not cfg.readings:
        raise ValueError("this model has no reading tokens (ModelConfig.readings is 0)")
    return replace(cfg, reading=READINGS.index(reading))


def retag_model(path: str | os.PathLike, dest: str | os.PathLike, meta: dict, reading: str | None = None) -> None:
    """Write model file ``path`` to ``dest`` with ``meta`` merged into its metadata (the
    poser defaults it carries), and answering in ``reading`` if given, with every tensor as
    it was, bit for bit: a shipped file's defaults can change without its training run at hand."""
    obj = _model_file(path)
    obj["model_config"] = with_reading(ModelConfig.from_dict(obj["model_config"]), reading).to_dict()
    obj["meta"] = {**(obj.get("meta") or {}), **meta}
    atomic_torch_save(obj, dest)


def _model_file(path: str | os.PathLike) -> dict:
    obj = _read_file(path)
    if not isinstance(obj, dict) or obj.get("format") != MODEL_FORMAT or "state_dict" not in obj:
        raise ModelFileError(path, "not an imucap model file (a training checkpoint exports with --out RUN)")
    return obj


def blend_models(path_a: str | os.PathLike, path_b: str | os.PathLike, weight: float,
                 dest: str | os.PathLike, meta: dict | None = None) -> None:
    """Write ``(1 - weight) * A + weight * B``, weight by weight, as a model file with A's
    config, normaliser and metadata (``meta`` merged in).

    Why: a fine-tune of A on new data (B) gains there and loses some of what A knew; the
    mix of the two networks keeps more of A than B does, and gains more than its share
    of B's new ground (weight-space ensembling, as WiSE-FT does for fine-tuned image
    models). That holds only for two files of one network fine-tuned from one start,
    so both must share the network and the feature normaliser; anything else is refused."""
    if not 0.0 <= weight <= 1.0:
        raise ValueError(f"blend weight {weight:g} outside 0..1 (0 is {os.fspath(path_a)}, 1 is {os.fspath(path_b)})")
    a, b = _model_file(path_a), _model_file(path_b)
    if a["kind"] != b["kind"]:
        raise ModelFileError(path_b, f"a {b['kind']} model; {os.fspath(path_a)} is a {a['kind']} model")
    sa, sb = a["state_dict"], b["state_dict"]
    if set(sa) != set(sb) or any(sa[k].shape != sb[k].shape for k in sa):
        raise ModelFileError(path_b, f"a different network from {os.fspath(path_a)}'s (layers or sizes differ)")
    if not (np.array_equal(a["norm_mean"], b["norm_mean"]) and np.array_equal(a["norm_std"], b["norm_std"])):
        raise ModelFileError(path_b, f"normalises features differently from {os.fspath(path_a)}: blend only a "
                                     "file with its own fine-tune (imucap train --init)")
    out = {}
    for k, va in sa.items():
        vb = sb[k]
        out[k] = ((1.0 - weight) * va.float() + weight * vb.float()).to(va.dtype) if va.is_floating_point() else va
    a["state_dict"] = out
    a["meta"] = {**(a.get("meta") or {}), **(meta or {}),
                 "blend": {"a": os.fspath(path_a), "b": os.fspath(path_b), "weight": float(weight)}}
    atomic_torch_save(a, dest)


def load_model(path: str | os.PathLike, use_ema: bool = True, window: int | None = None) -> LoadedModel:
    """Load an inference model file or a training checkpoint (its EMA weights by default),
    in eval mode, float32, on the CPU; reading ``window`` frames (``with_window``), by default
    those its file asks for (``meta["window"]``), else all it was trained on."""
    obj = _read_file(path)
    if not isinstance(obj, dict) or "model_config" not in obj:
        raise ModelFileError(path, f"not an imucap model file or training checkpoint (it holds {_what(obj)})")
    try:
        kind = obj["kind"]
        cfg = ModelConfig.from_dict(obj["model_config"])
        model = build_model(kind, cfg)
        if "state_dict" in obj:
            sd = obj["state_dict"]
        else:
            sd = obj["ema"] if use_ema and obj.get("ema") is not None else obj["model"]
        norm_mean = np.asarray(obj["norm_mean"], np.float32)
        norm_std = np.asarray(obj["norm_std"], np.float32)
    except KeyError as exc:
        raise ModelFileError(path, f"incomplete model file (no {_first_line(exc)!r})") from None
    except (ValueError, TypeError, AttributeError) as exc:
        raise ModelFileError(path, f"not a usable model file ({_first_line(exc)})") from None
    try:
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in sd.items()})
    except (RuntimeError, AttributeError, TypeError) as exc:
        raise ModelFileError(path, f"its weights do not fit the {kind} network its config describes "
                                   f"({' '.join(str(exc).split())[:200]})") from None
    if not (np.all(np.isfinite(norm_mean)) and np.all(np.isfinite(norm_std))):
        raise ModelFileError(path, "damaged model file (non-finite feature normaliser)")
    model.eval()
    loaded = LoadedModel(model=model, kind=kind, config=cfg, norm_mean=norm_mean, norm_std=norm_std,
                         step=int(obj.get("step", 0)), meta=obj.get("meta"))
    live = window if window is not None else (loaded.meta or {}).get("window")
    if live is not None and int(live) != cfg.window:
        try:
            loaded = with_window(loaded, int(live))
        except ValueError as exc:
            raise ModelFileError(path, str(exc)) from None
    return loaded


def newest_positions(pos: Tensor, window: int) -> Tensor:
    """A denoiser's learned positions (1, 2 + N, d) for the newest ``window`` of its N frames:
    the step and height tokens' two, then the last ``window`` frames' (the newest keeps its own)."""
    return torch.cat([pos[:, :2], pos[:, pos.shape[1] - window:]], dim=1)


def with_window(model: LoadedModel, window: int) -> LoadedModel:
    """``model`` reading the last ``window`` frames of the history it was trained on: the
    same weights, the learned positions of the frames it keeps (the newest frame keeps its
    own position, the oldest ones are dropped).

    Why a model file may ask for it (``meta["window"]``): with the one-step sampler the
    denoiser trained on 61-frame windows scores better on the held-out people given only
    the last second (docs/model.md, "How much history"), and every pass is then a third of
    the arithmetic. Same window: the model itself."""
    if window == model.config.window:
        return model
    if model.kind != "diffusion":
        raise ValueError(f"a {model.kind} model reads its whole {model.config.window}-frame window")
    if not 2 <= window <= model.config.window:
        raise ValueError(f"live window {window}: the model was trained on {model.config.window} frames "
                         "(a shorter window keeps the newest of them; 2 at least)")
    cfg = replace(model.config, window=window)
    net = build_model(model.kind, cfg)
    sd = dict(model.model.state_dict())
    sd["pos"] = newest_positions(sd["pos"], window)
    net.load_state_dict(sd)
    net.eval()
    meta = {**(model.meta or {}), "window": window, "trained_window": model.config.window}
    return replace(model, model=net, config=cfg, meta=meta)


