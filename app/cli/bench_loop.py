"""The frames every ``imucap bench`` table is measured on, and how posers are stepped over
them: one generated walk, and every poser of a comparison stepped on the same frame in
turn, so the shared machine's moment falls on all of them alike (only ratios from one run
compare). ``app/cli/bench.py`` builds its tables on these; ``benchmarks/poser_stages.py``
too."""

from __future__ import annotations

import time

import numpy as np


def walk_input(n_frames: int, seed: int):
    """A generated walking clip (at least ``n_frames`` at 20 Hz) and its input at the paper's 6 sites."""
    from inference.evaluation.runner import SIX, clip_input, synthetic_motion

    motion = synthetic_motion(seconds=max(2.0, n_frames / 20.0 + 0.5), seed=seed)
    return motion, clip_input(motion, SIX)


STAGES = ("observe", "enter", "model", "finish")
"""``Poser.step``'s stages: the observation, the window's shift, the model call (``_predict``), and
everything after it (cleaning, contacts, FK, root, filters, the PoseFrame)."""


def stage_times(posers: dict, inp, frames: int, warmup: int = 10) -> dict[str, dict[str, np.ndarray]]:
    """Each poser's thread CPU time (ms) of each of ``STAGES`` per frame (``<stage>_cpu``), and the
    wall time (``<stage>_wall``), the posers stepped in turn as ``interleaved_times`` does."""
    import torch

    names = list(posers)
    n = inp.features.shape[0]
    out = {name: {f"{s}_{k}": np.empty(frames) for s in STAGES for k in ("wall", "cpu")} for name in names}
    for i in range(warmup + frames):
        k = i % n
        r = i % len(names)
        for name in names[r:] + names[:r]:
            p = posers[name]
            with torch.inference_mode():
                t = [(time.perf_counter(), time.thread_time())]
                obs = p.observe(inp.features[k], inp.mask[k])
                t.append((time.perf_counter(), time.thread_time()))
                win, mask = p.enter(obs)
                t.append((time.perf_counter(), time.thread_time()))
                y = p._predict(win, mask)[0, -1]
                t.append((time.perf_counter(), time.thread_time()))
                p.finish(y, win, obs)
                t.append((time.perf_counter(), time.thread_time()))
            if i >= warmup:
                for j, s in enumerate(STAGES):
                    out[name][f"{s}_wall"][i - warmup] = (t[j + 1][0] - t[j][0]) * 1e3
                    out[name][f"{s}_cpu"][i - warmup] = (t[j + 1][1] - t[j][1]) * 1e3
    return out


def interleaved_times(posers: dict, inp, frames: int, warmup: int) -> dict[str, np.ndarray]:
    """Step every poser on the same frames, one after the other within each frame, the
    order turning by one each frame: the shared machine's load changes within seconds, and
    timing one poser after the other would hand the difference to whichever ran in the
    quieter stretch. Returns each poser's timed frames in ms."""
    names = list(posers)
    n = inp.features.shape[0]
    ms = {name: np.empty(frames) for name in names}
    for i in range(warmup + frames):
        k = i % n
        r = i % len(names)
        for name in names[r:] + names[:r]:
            t0 = time.perf_counter()
            posers[name].step(inp.features[k], inp.mask[k])
            if i >= warmup:
                ms[name][i - warmup] = (time.perf_counter() - t0) * 1e3
    return ms


__all__ = ["STAGES", "walk_input", "stage_times", "interleaved_times"]
