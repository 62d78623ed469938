"""Foot contacts from the two shank sensors, for the root correction.

Why a separate stage: the root path is integrated from the model's root displacement
corrected by the feet predicted in contact (paper sec. 3.4.2), and a foot wrongly taken as
planted cancels a step. The reconstruction models predict contacts as 4 of 190 features;
on the held-out Bandai walks the shipped diffusion model got them right in only 26-80 % of
the frames. Stance versus swing is, however, plain in a shank sensor's own signals (a
planted shank turns slowly about the ankle; a swinging one turns fast and accelerates), so
a small causal classifier on the last ``CONTEXT`` frames of both shanks gets ~95 % there.

It needs both shanks measured (the paper's 6-site set and the 2-site shank set have
them); without them, or with insoles, the poser keeps the model's own contacts.

Inputs per frame (18 numbers): each shank's orientation (6D) and acceleration, turned
about the vertical into the frame that faces the two shanks' mean heading. That makes
them heading-invariant without needing the pelvis, and mirror augmentation keeps the
two sides alike.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from inference.body.conventions import turn_cs
from inference.body.rotations import facing_x, matrix_to_rot6d, rot6d_to_matrix, rot6d_to_matrix_np
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.features.layout import SL_ACC, SL_CONTACT, SL_ROT
from inference.poser.small_nets import FitConfig, NumpyMLP, clip_tensors, fit, load_net, save_net, stack_context

DETECTOR_FORMAT = "imucap-contact-detector-v1"
CONTEXT = 9  # frames at 20 Hz (0.45 s, this one and the 8 before)
SHANKS = ("l_shank", "r_shank")
DETECTOR_THRESHOLD = 0.5  # a calibrated classifier: probability above one half = planted


def shank_feature_index() -> np.ndarray:
    """(18,) indices into a 190-feature frame: left, right shank 6D, then left, right
    shank-site acceleration."""
    rot = [SL_ROT.start + 6 * SEGMENT_INDEX[s] + k for s in SHANKS for k in range(6)]
    acc = [SL_ACC.start + 3 * SITE_INDEX[s] + k for s in SHANKS for k in range(3)]
    return np.asarray(rot + acc)


SHANK_INDEX = shank_feature_index()


def heading_frame_inputs(shank: Tensor) -> Tensor:
    """(..., 18) raw shank features (``SHANK_INDEX`` order, physical units) -> (..., 18)
    the same turned about world z so the mean heading of the shanks' x axes is +X."""
    R = rot6d_to_matrix(shank[..., :12].reshape(*shank.shape[:-1], 2, 6))  # (..., 2, 3, 3)
    h = R[..., 0, :2, 0] + R[..., 1, :2, 0]
    Rz = facing_x(h)  # R_z(-yaw)
    rot = matrix_to_rot6d(Rz[..., None, :, :] @ R).reshape(*shank.shape[:-1], 12)
    acc = (Rz[..., None, :, :] @ shank[..., 12:].reshape(*shank.shape[:-1], 2, 3, 1)).reshape(*shank.shape[:-1], 6)
    return torch.cat([rot, acc], dim=-1)


def heading_frame_inputs_np(shank: np.ndarray) -> np.ndarray:
    """``heading_frame_inputs`` of (C, 18) float32 frames on numpy (the live poser's path).
    Only the 6D of ``R_z(-yaw) @ R`` is needed, i.e. the turned first two columns of R:
    the turn is applied to those and to the accelerations, written out about z."""
    C = shank.shape[0]
    R = rot6d_to_matrix_np(shank[:, :12].reshape(C, 2, 6))  # (C, 2, 3, 3)
    h = R[:, 0, :2, 0] + R[:, 1, :2, 0]
    yaw = np.arctan2(h[:, 1], h[:, 0])[:, None, None]
    c, s = np.cos(yaw), np.sin(yaw)
    # (C, 2 shanks, 3 vectors: column 0, column 1, acceleration, xyz)
    v = np.concatenate([np.swapaxes(R[..., :2], -1, -2), shank[:, 12:].reshape(C, 2, 1, 3)], axis=2)
    out = turn_cs(v, c, -s)  # R_z(-yaw)
    return np.concatenate([out[:, :, :2].reshape(C, 12), out[:, :, 2].reshape(C, 6)], axis=1)


class DetectorKernel:
    """A ContactDetector's ``probabilities`` on numpy (``small_nets.NumpyMLP``), for the live
    poser's per-frame path; a copy of its weights at construction."""

    def __init__(self, det: ContactDetector) -> None:
        self.context = det.context
        self.mlp = NumpyMLP(det)

    def __call__(self, shank_frames: np.ndarray) -> np.ndarray:
        """(context, 18) float32 raw shank features of the last frames (oldest first) -> (4,)."""
        logits = self.mlp(heading_frame_inputs_np(shank_frames).reshape(1, -1))[0]
        return np.float32(1.0) / (np.float32(1.0) + np.exp(-logits))


def context_windows(x: np.ndarray | Tensor, context: int = CONTEXT) -> Tensor:
    """(T, 190) one clip's features -> (T, context * 18): per frame, that frame and the
    ``context - 1`` before it (the first frame repeated before the start), heading-framed."""
    f = heading_frame_inputs(torch.as_tensor(np.asarray(x)[:, SHANK_INDEX], dtype=torch.float32))
    return stack_context(f, context).reshape(f.shape[0], -1)


class ContactDetector(nn.Module):
    """MLP on ``context`` heading-framed shank frames -> 4 contact logits (l_heel, l_toe,
    r_heel, r_toe). The input normaliser travels with the weights."""

    def __init__(self, context: int = CONTEXT, hidden: int = 128) -> None:
        super().__init__()
        self.context, self.hidden = context, hidden
        self.meta: dict = {}  # what it was trained on and how it scored (saved with it)
        n = context * len(SHANK_INDEX)
        self.register_buffer("in_mean", torch.zeros(n))
        self.register_buffer("in_std", torch.ones(n))
        self.net = nn.Sequential(nn.Linear(n, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, 4))

    def forward(self, windows: Tensor) -> Tensor:
        return self.net((windows - self.in_mean) / self.in_std)

    @torch.no_grad()
    def probabilities(self, shank_frames: Tensor) -> Tensor:
        """(context, 18) raw shank features of the last frames (oldest first) -> (4,)."""
        w = heading_frame_inputs(shank_frames.to(torch.float32)).reshape(1, -1)
        return torch.sigmoid(self(w))[0]


# --------------------------------------------------------------------------- training

@dataclass
class DetectorTraining(FitConfig):
    context: int = CONTEXT
    hidden: int = 128


def clip_windows(clips: Sequence[np.ndarray], context: int = CONTEXT, mirror: bool = False) -> tuple[Tensor, Tensor]:
    """Inputs (n, context * 18) and contact labels (n, 4) of every frame of every clip."""
    X, Y = [], []
    for x in clip_tensors(clips, mirror):
        X.append(context_windows(x, context))
        Y.append(x[:, SL_CONTACT])
    return torch.cat(X), torch.cat(Y)


def contact_accuracy(det: ContactDetector, X: Tensor, Y: Tensor, threshold: float = 0.5) -> list[float]:
    """Per-point share of frames classified right."""
    with torch.no_grad():
        p = torch.sigmoid(det(X))
    return ((p > threshold) == (Y > 0.5)).double().mean(0).tolist()


def train_detector(train_clips: Sequence[np.ndarray], val_sets: dict[str, Sequence[np.ndarray]] | None = None,
                   cfg: DetectorTraining | None = None, progress=print) -> ContactDetector:
    """Fit a detector to every frame of ``train_clips`` (and their mirror images); logs
    per-point accuracy on each validation set every 1000 steps into ``cfg.log``."""
    cfg = cfg or DetectorTraining()
    X, Y = clip_windows(train_clips, cfg.context)
    val = {k: clip_windows(v, cfg.context) for k, v in (val_sets or {}).items()}
    torch.manual_seed(cfg.seed)  # the initial weights
    det = ContactDetector(cfg.context, cfg.hidden)
    det.in_mean.copy_(X.mean(0))
    det.in_std.copy_(X.std(0).clamp(min=1e-3))
    scores = lambda: {f"acc_{k}": [round(a, 3) for a in contact_accuracy(det, *v)]  # noqa: E731
                      for k, v in val.items()}
    return fit(det, (X, Y), clip_windows(train_clips, cfg.context, mirror=True), cfg,
               F.binary_cross_entropy_with_logits, scores, progress)


# --------------------------------------------------------------------------- files

def save_detector(path: str | os.PathLike, det: ContactDetector, meta: dict | None = None) -> None:
    save_net(path, DETECTOR_FORMAT, det, meta)


def load_detector(path: str | os.PathLike) -> ContactDetector:
    return load_net(path, DETECTOR_FORMAT, ContactDetector, "contact detector")
