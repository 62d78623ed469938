"""Model files: build a fresh network of a kind, save and load inference files and
training checkpoints. Above the denoiser and the regressor, the one place that knows both."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from inference.model.config import ModelConfig, atomic_torch_save
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


def retag_model(path: str | os.PathLike, dest: str | os.PathLike, meta: dict) -> None:
    """Write model file ``path`` to ``dest`` with ``meta`` merged into its metadata (the
    poser defaults it carries) and every tensor as it was, bit for bit: a shipped file's
    defaults can change without its training run at hand."""
    obj = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(obj, dict) or obj.get("format") != MODEL_FORMAT or "state_dict" not in obj:
        raise ValueError(f"{path} is not an imucap model file (a training checkpoint exports with --out RUN)")
    obj["meta"] = {**(obj.get("meta") or {}), **meta}
    atomic_torch_save(obj, dest)


def load_model(path: str | os.PathLike, use_ema: bool = True) -> LoadedModel:
    """Load an inference model file or a training checkpoint (its EMA weights by default),
    in eval mode, float32, on the CPU."""
    obj = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(obj, dict) or "model_config" not in obj:
        raise ValueError(f"{path} is not an imucap model file or training checkpoint")
    kind = obj["kind"]
    cfg = ModelConfig.from_dict(obj["model_config"])
    model = build_model(kind, cfg)
    if "state_dict" in obj:
        sd = obj["state_dict"]
    else:
        sd = obj["ema"] if use_ema and obj.get("ema") is not None else obj["model"]
    model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in sd.items()})
    model.eval()
    return LoadedModel(model=model, kind=kind, config=cfg, norm_mean=np.asarray(obj["norm_mean"], np.float32),
                       norm_std=np.asarray(obj["norm_std"], np.float32), step=int(obj.get("step", 0)),
                       meta=obj.get("meta"))


