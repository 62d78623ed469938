"""An untrained tiny diffusion model for the poser's tests: the code paths, not the answers."""

from __future__ import annotations

import numpy as np
import torch

from inference.features.layout import N_FEATURES
from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, build_model


def tiny_diffusion(mask_input: bool = True) -> LoadedModel:
    """The same weights on every call (seeded), an identity feature normaliser."""
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    cfg.mask_input = mask_input
    return LoadedModel(model=build_model("diffusion", cfg).eval(), kind="diffusion", config=cfg,
                       norm_mean=np.zeros(N_FEATURES, np.float32), norm_std=np.ones(N_FEATURES, np.float32))
