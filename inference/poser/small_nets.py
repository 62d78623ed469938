"""What the poser's small helper networks share (the shank contact detector, the pelvis
odometry): causal context windows, one training loop, one file layout.

Why they exist beside the reconstruction model: each answers one question the poser's
root correction needs (which foot is planted; how far the pelvis walked) from a second
or less of one or two sensors, where a 40-200 k-parameter MLP trained on every frame
of the training split in a minute beats what the full model says about it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn


def stack_context(f: Tensor, context: int) -> Tensor:
    """(T, n) per-frame inputs -> (T, context, n): per frame, it and the ``context - 1``
    before it, the first frame repeated before the start (as the poser's standing history
    repeats the calibration pose)."""
    pad = torch.cat([f[:1].expand(context - 1, -1), f], dim=0)
    idx = torch.arange(f.shape[0])[:, None] + torch.arange(context)[None]
    return pad[idx]


class NumpyMLP:
    """An eval-mode ``nn.Sequential`` of Linear and GELU layers as float32 numpy matmuls,
    with the input normaliser ``(x - in_mean) / in_std`` of the helper nets: the live poser
    calls a helper on one frame, where torch's per-call cost is most of the time. A copy
    of the weights at construction. For one row at a time: a batch goes through OpenBLAS's
    gemm, whose threads spin on a busy 2-core machine (a 20x256x256 call took 8 ms of CPU)."""

    def __init__(self, net: nn.Module) -> None:
        from scipy.special import erf

        self._erf = erf
        self.in_mean = net.in_mean.detach().numpy().astype(np.float32)
        self.in_std = net.in_std.detach().numpy().astype(np.float32)
        self.layers: list[tuple[np.ndarray, np.ndarray] | None] = []
        for layer in net.net:
            if isinstance(layer, nn.Linear):
                self.layers.append((np.ascontiguousarray(layer.weight.detach().numpy().T, dtype=np.float32),
                                    layer.bias.detach().numpy().astype(np.float32)))
            elif isinstance(layer, nn.GELU) and layer.approximate == "none":
                self.layers.append(None)
            else:
                raise TypeError(f"NumpyMLP takes Linear and exact GELU layers, not {layer}")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(B, n) inputs -> (B, out) the net's outputs (before any sigmoid or output scale)."""
        h = (x - self.in_mean) / self.in_std
        for layer in self.layers:
            if layer is None:
                h = h * np.float32(0.5) * (np.float32(1.0) + self._erf(h * np.float32(0.7071067811865476)))
            else:
                h = h @ layer[0] + layer[1]
        return h


def clip_tensors(clips: Sequence[np.ndarray], mirror: bool = False) -> Iterator[Tensor]:
    """Each clip's (T, 190) features as float32 tensors, or their mirror images: what
    every helper's training windows are cut from."""
    from inference.features.mirror import mirror_features

    for x in clips:
        x = torch.as_tensor(np.asarray(x, dtype=np.float32))
        yield mirror_features(x) if mirror else x


@dataclass
class FitConfig:
    """How ``fit`` trains a helper network; each network's own config subclasses this
    with its defaults (and its ``context`` and ``hidden`` size)."""

    steps: int = 6000
    batch: int = 512
    lr: float = 1e-3
    weight_decay: float = 1e-4
    input_noise: float = 0.05  # in normalised units: sensor noise and other bodies
    mirror: float = 0.5  # share of windows mirrored left <-> right
    seed: int = 0
    context: int = 1
    hidden: int = 128
    log: list[dict] = field(default_factory=list)


def fit(net: nn.Module, data: tuple[Tensor, Tensor], mirrored: tuple[Tensor, Tensor], cfg: FitConfig,
        loss_fn: Callable[[Tensor, Tensor], Tensor], scores: Callable[[], dict], progress=print) -> nn.Module:
    """Minibatch AdamW with a cosine schedule over every frame's window (inputs, targets),
    drawing a ``cfg.mirror`` share from the mirror images; Gaussian input noise of
    ``cfg.input_noise`` input standard deviations (``net.in_std``: sensor noise and other
    bodies); the batches are drawn from ``cfg.seed`` (the caller seeds the initial
    weights). Every 1000 steps and at the end, ``scores()`` (in eval mode) goes into
    ``cfg.log`` and to ``progress``."""
    g = torch.Generator().manual_seed(cfg.seed)
    X, Y = data
    Xm, Ym = mirrored
    opt = torch.optim.AdamW(net.parameters(), cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps, eta_min=cfg.lr * 0.05)
    t0 = time.time()
    for step in range(1, cfg.steps + 1):
        i = torch.randint(0, X.shape[0], (cfg.batch,), generator=g)
        flip = (torch.rand(cfg.batch, generator=g) < cfg.mirror)[:, None]
        xb = torch.where(flip, Xm[i], X[i])
        yb = torch.where(flip, Ym[i], Y[i])
        xb = xb + cfg.input_noise * net.in_std * torch.randn(xb.shape, generator=g)
        loss = loss_fn(net(xb), yb)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 1000 == 0 or step == cfg.steps:
            net.eval()
            entry = {"step": step, "loss": float(loss.detach()), "sec": round(time.time() - t0, 1), **scores()}
            net.train()
            cfg.log.append(entry)
            if progress:
                progress(entry)
    return net.eval()


def net_entry(net: nn.Module) -> dict:
    """What rebuilds a helper network: its constructor's context and hidden size, and weights."""
    return {"context": net.context, "hidden": net.hidden, "state_dict": net.state_dict()}


def net_from_entry(entry: dict, cls: type) -> nn.Module:
    net = cls(int(entry["context"]), int(entry["hidden"]))
    net.load_state_dict(entry["state_dict"])
    return net.eval()


def save_file(path: str | os.PathLike, obj: dict) -> None:
    from inference.model.config import atomic_torch_save

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(obj, path)


def read_file(path: str | os.PathLike, formats: tuple[str, ...], what: str) -> dict:
    """A helper-stage file's contents; a clear error for any other file."""
    obj = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(obj, dict) or obj.get("format") not in formats:
        raise ValueError(f"{path} is not an imucap {what} file")
    return obj


def save_net(path: str | os.PathLike, fmt: str, net: nn.Module, meta: dict | None = None) -> None:
    """One file: the format tag, the constructor's context and hidden size, weights, meta."""
    save_file(path, {"format": fmt, **net_entry(net), "meta": meta or {}})


def load_net(path: str | os.PathLike, fmt: str, cls: type, what: str):
    """The network ``save_net`` wrote, in eval mode; a clear error for any other file."""
    obj = read_file(path, (fmt,), what)
    net = net_from_entry(obj, cls)
    net.meta = obj.get("meta", {})
    return net
