"""The training losses (paper eq. 5-10) on predictions mapped back to physical units, and
how they are weighted into one number."""

from __future__ import annotations

import functools

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from inference.body.body import Body, contact_points, forward_kinematics
from inference.body.rotations import rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.features.layout import SL_CONTACT, SL_DP, SL_PZ, SL_ROT, observation_mask
from inference.signals.resample import FPS_MODEL
from inference.training.config import LossWeights, TrainConfig


def contact_offsets_for(offsets: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """(B, 4, 3) heel/toe points of each sample's body (as the body model places them)."""
    return np.stack([Body.from_offsets(o, float(h)).contact_offsets for o, h in zip(offsets, heights)])


def sites_known_share(known: Tensor, sites: list[str] | tuple[str, ...]) -> Tensor:
    """(B,) share of each window's frames in which every one of `sites` has its orientation
    known, from a (B, N, F) known-entry mask: the swing term's per-window weight
    (``TrainConfig.swing_gate``)."""
    return known[..., _orientation_columns(tuple(sites))].all(-1).float().mean(-1)


@functools.lru_cache(maxsize=8)
def _orientation_columns(sites: tuple[str, ...]) -> Tensor:
    """Feature columns of the sites' orientations, built once: the gate runs on every
    training step (the accelerations come with the orientations, so they need no check)."""
    cols = observation_mask(list(sites))
    cols[SL_ROT.stop:] = False
    return torch.as_tensor(cols)


# knees, ankles and toes: the origins of the shank, foot and toe segments
_LEG_JOINTS = [SEGMENT_INDEX[n] for n in ("l_shank", "r_shank", "l_foot", "r_foot", "l_toes", "r_toes")]


def motion_losses(pred_n: Tensor, true_n: Tensor, mean: Tensor, std: Tensor, offsets: Tensor,
                  contact_local: Tensor, swing_weight: Tensor | None = None,
                  answer_lag: int = 0) -> dict[str, Tensor]:
    """Unweighted loss terms (scalars) for predicted vs. true normalised windows (B, N, F).

    offsets (B, 24, 3) rest bone offsets; contact_local (B, 4, 3) heel/toe points on their
    segments. swing_weight (B,) weighs each window's swing term (``sites_known_share``; None =
    1 for all). ``answer_lag``: the "last" terms weigh the frame this many before the
    newest (``TrainConfig.answer_lag``). See ``LossWeights`` for the units.
    """
    B, N, _ = pred_n.shape
    pred = pred_n * std + mean
    true = true_n * std + mean
    terms: dict[str, Tensor] = {"simple": F.mse_loss(pred_n, true_n)}

    r6p = pred[..., SL_ROT].reshape(B, N, N_SEGMENTS, 6)
    r6t = true[..., SL_ROT].reshape(B, N, N_SEGMENTS, 6)
    dv = (r6p[:, 1:] - r6p[:, :-1]) - (r6t[:, 1:] - r6t[:, :-1])
    terms["vel"] = (dv * FPS_MODEL).square().sum(-1).mean()

    Rp = rot6d_to_matrix(r6p)
    Rt = rot6d_to_matrix(r6t)
    off = offsets[:, None].to(pred.dtype)
    zero = torch.zeros(B, N, 3, dtype=pred.dtype)
    jp = forward_kinematics(Rp, zero, off)
    jt = forward_kinematics(Rt, zero, off)
    fk_err = (jp - jt).square().sum(-1)
    terms["fk"] = fk_err.mean()
    a = -1 - answer_lag
    terms["last"] = F.mse_loss(pred_n[:, a], true_n[:, a])
    terms["fk_last"] = fk_err[:, a].mean()

    lp, lt = jp[:, :, _LEG_JOINTS], jt[:, :, _LEG_JOINTS]
    spread_p = (lp.var(dim=1, unbiased=False) + 1e-8).sqrt()  # eps: no inf gradient at rest
    spread_t = (lt.var(dim=1, unbiased=False) + 1e-8).sqrt()
    swing = (spread_p - spread_t).square().sum(-1).mean(-1)  # (B,)
    terms["swing"] = swing.mean() if swing_weight is None else (swing_weight * swing).mean()

    pp = torch.cumsum(pred[..., SL_DP], dim=1)
    pt = torch.cumsum(true[..., SL_DP], dim=1)
    terms["drift"] = (pp - pt).square().sum(-1).mean()

    # foot slide: predicted contact at frame i x world velocity of that foot point from
    # frame i to i+1 (relative FK motion + root displacement of frame i+1 + root height
    # change). The contact weight is detached: this term should move the feet, not
    # teach the model to predict "no contact" (the simple term supervises contacts).
    cp = contact_points(Rp, jp, contact_local[:, None].to(pred.dtype))  # (B, N, 4, 3)
    root_step = torch.cat([pred[:, 1:, SL_DP], pred[:, 1:, SL_PZ] - pred[:, :-1, SL_PZ]], dim=-1)
    v = (cp[:, 1:] - cp[:, :-1] + root_step[:, :, None]) * FPS_MODEL
    w = pred[:, :-1, SL_CONTACT].clamp(0.0, 1.0).detach()
    terms["slide"] = (w * v.square().sum(-1)).mean()
    return terms


def inpaint_mode_for(cfg: TrainConfig) -> str:
    """How a model trained with `cfg` should inpaint: the way it saw known entries."""
    return "replace" if cfg.kind == "diffusion" and cfg.cond_prob > 0 else "paper"


def total_loss(terms: dict[str, Tensor], weights: LossWeights) -> Tensor:
    return sum(getattr(weights, k) * v for k, v in terms.items())
