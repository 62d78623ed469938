"""Offline reconstruction with the model calls of many frames in one batch.

Two ways, both running every frame through the poser's own stages (``observe``,
``enter``, ``finish``: cleaning, contacts, root correction, odometry, stride scaling,
output filters and the history, in order), so only the model calls are shared:

- ``reconstruct_many``: several clips in lock step, each with its own poser, one frame of
  each per call. Every window is exactly the one its poser builds frame by frame, so each
  clip's answer is its frame-by-frame one to float tolerance (the batch changes only the
  order of float sums: ~1e-6). ``imucap evaluate`` and ``imucap advise`` use it.
- ``reconstruct_batched``: one clip cut into chunks of frames inpainted together. With
  the shipped settings (history "measured", "replace-ddim" from the prior's mean) the
  model is told only the measurements of its window; the reconstructed history is the
  starting guess of the unknown entries, scaled by sqrt(alpha_bar(T)) = 5e-5 before the
  first call, so a chunk's own earlier frames can be guessed (the last finished frame
  carried forward, what the live loop does for a new frame's unknowns). The guess still
  moves the answer by up to ~2e-4 (rotation entries, metres), which is more than float
  tolerance; on one thread it gains nothing either (the denoiser is compute-bound already
  at the live loop's two windows), so nothing ships with it: it is here for machines with
  free cores, where a batch lets them share one call.

Where the answer depends on the history (the regressor, the floor, history
"reconstructed", noise drawn per step), or the posers do not share one model, the clips
run frame by frame instead.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch
from torch import Tensor

from inference.features.layout import N_FEATURES
from inference.model.diffusion import inpaint
from inference.poser.poser import Observation, Poser, Reconstruction, reconstruct_offline

DEFAULT_CHUNK = 8  # frames per batch: 16 windows with mirror averaging, the fastest per window on 1-2 threads


def batchable(poser: Poser) -> bool:
    """Whether frames of a clip can share model calls without changing the answer."""
    return (poser.kind == "diffusion" and poser.history_mode == "measured" and poser.noise_mode == "mean"
            and poser.inpaint_mode == "replace-ddim" and not poser.takes_points)


def reconstruct_batched(poser: Poser, features: np.ndarray, mask: np.ndarray, chunk: int = DEFAULT_CHUNK,
                        progress: Callable[[int], object] | None = None) -> Reconstruction:
    """``poser.reconstruct_offline`` with the model calls of ``chunk`` frames batched:
    features (T, 190), mask (T, 190) or (190,) bool; the poser continues from its state
    as ``step`` would. Falls back to frame by frame when the poser is not ``batchable``."""
    if not batchable(poser) or chunk <= 1:
        return reconstruct_offline(poser, features, mask, progress)
    features = np.asarray(features)
    T = features.shape[0]
    mask = np.ascontiguousarray(np.broadcast_to(np.asarray(mask, dtype=bool), (T, N_FEATURES)))
    frames = []
    with torch.inference_mode():
        obs = [poser.observe(features[t], mask[t]) for t in range(T)]
        for s in range(0, T, chunk):
            part = obs[s: s + chunk]
            wins, masks = _windows(poser, part)
            out = _inpaint(poser, wins, masks, poser._height.expand(len(part)), chunk)
            due = [poser.confidence is not None and (poser.index + j) % poser.confidence.every == 0
                   for j in range(len(part))]
            draws = _draws(poser, out, wins, masks, due, chunk) if any(due) else None
            k = 0
            for j, o in enumerate(part):
                win, _ = poser.enter(o)
                d = None
                if due[j]:
                    n = poser.confidence.draws
                    d, k = draws[k: k + n, -1], k + n
                frames.append(poser.finish(out[j, -1], win, o, d, poser.earlier_rows(out[j])))
                if progress is not None:
                    progress(1)
    return Reconstruction.of_frames(frames, poser)


def reconstruct_many(posers: Sequence[Poser], clips: Sequence[tuple[np.ndarray, np.ndarray]], lanes: int = 8,
                     progress: Callable[[int], object] | None = None,
                     points: Sequence[np.ndarray | None] | None = None) -> list[Reconstruction]:
    """Clips (features (T, 190), mask (T, 190) or (190,)) each through its own poser, the
    model calls of up to ``lanes`` clips in one batch: every clip's windows are exactly
    the ones its poser builds frame by frame, so each reconstruction equals
    ``reconstruct_offline`` of that clip to float tolerance. A lane whose clip ends takes
    the next clip. The posers must share one model and be ``batchable`` (else each clip
    runs frame by frame, which is also how clips with tracked ``points`` (T, 16) run)."""
    if len(posers) != len(clips):
        raise ValueError(f"{len(posers)} posers for {len(clips)} clips")
    if not posers:
        return []
    tracked = points is not None and any(p is not None for p in points)
    if tracked or not all(batchable(p) and p.model is posers[0].model for p in posers) or lanes <= 1:
        pts = points if points is not None else [None] * len(clips)
        return [reconstruct_offline(p, f, m, progress, pt) for p, (f, m), pt in zip(posers, clips, pts)]
    feats = [np.asarray(f) for f, _ in clips]
    masks = [np.ascontiguousarray(np.broadcast_to(np.asarray(m, dtype=bool), (len(f), N_FEATURES)))
             for f, (_, m) in zip(feats, clips)]
    out = [Reconstruction.empty(len(f)) for f in feats]
    frames: list[list] = [[] for _ in feats]
    queue = [i for i in range(len(clips)) if len(feats[i])]
    lanes = min(lanes, len(queue))
    active: list[list[int]] = []  # [clip, next frame]
    lead = posers[0]
    with torch.inference_mode():
        while queue or active:
            while queue and len(active) < lanes:
                active.append([queue.pop(0), 0])
            obs, wins, mks = [], [], []
            for i, t in active:
                o = posers[i].observe(feats[i][t], masks[i][t])
                w, mk = posers[i].enter(o)
                obs.append(o)
                wins.append(w)
                mks.append(mk)
            W, M = torch.cat(wins), torch.cat(mks)
            H = torch.cat([posers[i]._height for i, _ in active])
            y = _inpaint(lead, W, M, H, lanes)
            due = [posers[i].confidence_due() for i, _ in active]
            draws = None
            if any(due):
                noise = [posers[i].draw_noise() for (i, _), d in zip(active, due) if d]
                draws = _draws_of(lead, y, W, M, H, due, noise, lanes)
            k = 0
            for j, (i, _t) in enumerate(active):
                d = None
                if due[j]:
                    n = posers[i].confidence.draws
                    d, k = draws[k: k + n, -1], k + n
                frames[i].append(posers[i].finish(y[j, -1], wins[j], obs[j], d, posers[i].earlier_rows(y[j])))
                if progress is not None:
                    progress(1)
            for lane in active:
                lane[1] += 1
            done = [lane[0] for lane in active if lane[1] >= len(feats[lane[0]])]
            for i in done:
                out[i] = Reconstruction.of_frames(frames[i], posers[i])
                frames[i] = []
            active = [lane for lane in active if lane[1] < len(feats[lane[0]])]
    return out


def _windows(poser: Poser, part: list[Observation]) -> tuple[Tensor, Tensor]:
    """(c, N, F) windows and masks of the chunk's frames as the live loop would build them,
    the chunk's own earlier frames guessed as their measurements over the last finished
    frame carried forward."""
    N, c = poser.window, len(part)
    hist = poser.history_rows()  # (N, F) normalised, oldest first; the last row is the last finished frame
    hmask = poser.history_mask_rows()
    rows, mrows = [hist[1:]], [hmask[1:]]
    prev = hist[-1]
    for o in part:
        m = torch.from_numpy(o.m)
        prev = torch.where(m, torch.from_numpy(o.fn), prev)
        rows.append(prev[None])
        mrows.append(m[None])
    seq, mseq = torch.cat(rows), torch.cat(mrows)
    wins = seq.unfold(0, N, 1).permute(0, 2, 1)[:c]
    if poser.history_mode == "measured":
        masks = mseq.unfold(0, N, 1).permute(0, 2, 1)[:c]
    else:
        masks = torch.ones(c, N, N_FEATURES, dtype=torch.bool)
        masks[:, -1] = mseq[N - 1:]
    return wins.contiguous(), masks.contiguous()


def _pad(x: Tensor, n: int) -> Tensor:
    """``x`` grown to ``n`` along the batch by repeating its last entry (one traced shape)."""
    return x if x.shape[0] == n else torch.cat([x, x[-1:].expand(n - x.shape[0], *x.shape[1:])])


def _inpaint(poser: Poser, wins: Tensor, masks: Tensor, heights: Tensor, chunk: int) -> Tensor:
    """The answers (c, N, F) of c <= chunk windows, in one call of a fixed batch shape."""
    c = wins.shape[0]
    if poser.chain_mirror:
        # mirror averaging of whole chains (Poser._predict_chains), the chunk's windows and
        # their mirror images in one batch
        P, idx = poser.mirror_op.mirror, poser.mirror_op.idx
        w, m, h = _pad(wins, chunk), _pad(masks, chunk), _pad(heights, chunk)
        out = inpaint(poser.net_for(2 * chunk, mirror=False), torch.cat([w, P(w)]), torch.cat([m, m[..., idx]]),
                      torch.cat([h, h]), poser.steps, schedule=poser.schedule, mode=poser.inpaint_mode,
                      mask_input=poser.model.config.mask_input, start="mean", start_at=poser.start_at)
        return torch.where(m, w, 0.5 * (out[:chunk] + P(out[chunk:])))[:c]
    out = inpaint(poser.net_for(chunk), _pad(wins, chunk), _pad(masks, chunk), _pad(heights, chunk),
                  poser.steps, schedule=poser.schedule, mode=poser.inpaint_mode,
                  mask_input=poser.model.config.mask_input, start="mean", start_at=poser.start_at)
    return out[:c]


def _draws(poser: Poser, out: Tensor, wins: Tensor, masks: Tensor, due: list[bool], chunk: int) -> Tensor:
    """The draws of the chunk's due frames, their noise drawn frame by frame in order."""
    return _draws_of(poser, out, wins, masks, poser._height.expand(len(due)), due,
                     [poser.draw_noise() for d in due if d], chunk)


def _draws_of(poser: Poser, out: Tensor, wins: Tensor, masks: Tensor, heights: Tensor, due: list[bool],
              noise: list[Tensor], batch: int) -> Tensor:
    """(sum of draws, N, F) the draws of the due windows with their noise, in one call of
    a fixed batch shape."""
    idx = [j for j, d in enumerate(due) if d]
    k = poser.confidence.draws
    n = batch * k
    got = poser.draw(_pad(out[idx], batch), _pad(wins[idx], batch), _pad(masks[idx], batch),
                     _pad(torch.cat(noise), n), net=poser.draw_net_for(n), heights=_pad(heights[idx], batch))
    return got[: len(idx) * k]


__all__ = ["reconstruct_batched", "reconstruct_many", "batchable", "DEFAULT_CHUNK"]
