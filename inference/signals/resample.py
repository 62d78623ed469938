"""60 Hz -> 20 Hz as the model was trained, batch and streaming, plus irregular device
timestamps -> the 60 Hz grid.

The model sees acceleration after an 11-frame centred moving average at 60 Hz (current
frame, five past, five future: 166 ms) and then every 3rd frame (paper, sec. 3.3 and the
real-IMU experiment). Live, the streaming version does the same one sample at a time; its
output must be *identical* to the batch version's (training/evaluation uses batch, the live
loop uses streaming), so both share one summation routine that adds the 11 shifted
samples in the same order.

Edge handling (both versions): the sequence is padded by replicating its first sample 5
times at the front and its last sample 5 times at the back. At the front this is what a
subject standing still before the first sample would produce; at the back it lets a
finished recording emit its last frames (``flush``). Missing samples (NaN acceleration)
are left out of the average; an output is missing (NaN) only if its centre sample is.

Decimation phase: 20 Hz frame k is 60 Hz sample 3k (the first sample is always kept).

Causal (``causal=True``, the low-latency mode, docs/latency.md): the same 11 samples but
trailing (the current one and the ten before it), so a 20 Hz frame is ready the moment its
own sample arrives instead of 83 ms later. Same smoothing (same magnitude response), but the
acceleration then lags the orientation by 5 samples: a model must be trained on signals
filtered this way to read them right, so a model file says which filter it expects
(``acc_filter_of``). The front is padded with 10 replicas of the first sample; an output is
missing only if its own (newest) sample is. The centred filter is the default and is
computed exactly as before.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from inference.body.rotations import quat_normalize, quat_slerp

HALF = 5  # look-ahead / look-behind of the moving average, samples
WINDOW_MA = 2 * HALF + 1
FPS_SIGNAL = 60  # the rate every live stream is put on (the hub's grid) and synthesis works at
FPS_MODEL = 20  # the model's frame rate
STEP = FPS_SIGNAL // FPS_MODEL  # 60 Hz -> 20 Hz
ACC_FILTERS = ("centred", "causal")  # what a model file's meta["acc_filter"] may say


def _window_mean(stack: list[np.ndarray], anchor: int = HALF) -> np.ndarray:
    """Mean of the 11 arrays in `stack` (each (..., 3)), ignoring NaN, summed in list order
    so the streaming and batch versions give bit-identical results; missing where
    ``stack[anchor]`` (the sample the output stands for) is."""
    s = np.zeros_like(stack[0], dtype=np.float64)
    n = np.zeros(stack[0].shape, dtype=np.float64)
    for x in stack:
        ok = np.isfinite(x)
        s = s + np.where(ok, x, 0.0)
        n = n + ok
    with np.errstate(invalid="ignore", divide="ignore"):
        out = s / n
    centre = stack[anchor]
    return np.where(np.isfinite(centre), out, np.nan)


def moving_average(acc: np.ndarray, step: int = 1, causal: bool = False) -> np.ndarray:
    """Centred (or, with ``causal``, trailing) 11-frame moving average along axis 0 with
    edge-replicate padding, evaluated at samples 0, step, 2*step, ... (step=1: every
    sample; step=3: the 20 Hz frames)."""
    acc = np.asarray(acc, dtype=np.float64)
    T = acc.shape[0]
    if T == 0:
        return acc.copy()
    if causal:
        pad = np.concatenate([np.repeat(acc[:1], 2 * HALF, 0), acc], axis=0)
    else:
        pad = np.concatenate([np.repeat(acc[:1], HALF, 0), acc, np.repeat(acc[-1:], HALF, 0)], axis=0)
    n = len(range(0, T, step))
    # strided views, no copies: window element k of output i is pad[i*step + k]
    stack = [pad[k: k + (n - 1) * step + 1: step] for k in range(WINDOW_MA)]
    return _window_mean(stack, 2 * HALF) if causal else _window_mean(stack)


def downsample(acc: np.ndarray, rest: np.ndarray | None = None,
               causal: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Batch 60 -> 20 Hz: smoothed acceleration at every 3rd sample, and `rest` (e.g.
    orientations, contacts: anything not smoothed) taken at the same samples."""
    a = moving_average(acc, STEP, causal)
    r = None if rest is None else np.asarray(rest)[::STEP]
    return a, r


@dataclass
class Frame20:
    """One 20 Hz output of the streaming resampler.

    index: 20 Hz frame number (60 Hz sample 3*index); t: that sample's time (if given);
    acc: smoothed acceleration; rest: the unsmoothed payload of that sample."""

    index: int
    t: float | None
    acc: np.ndarray
    rest: np.ndarray | None


class StreamingResampler:
    """Stateful 60 -> 20 Hz: push one 60 Hz sample at a time; a 20 Hz frame comes out once
    the 5 samples after it have arrived (83 ms look-ahead), ``flush()`` emits the last ones
    at the end of a recording. Output equals ``downsample`` on the whole sequence.
    ``causal``: the trailing average; a frame comes out with its own sample (no look-ahead)
    and equals ``downsample(..., causal=True)``.

    Internally it keeps the last 11 samples of the *padded* sequence (5 replicas of the
    first sample in front, 10 when causal), so the window of sample c is exactly the buffer
    when padded sample c+10 arrives; one push can complete at most one window."""

    def __init__(self, causal: bool = False) -> None:
        self.causal = bool(causal)
        # where in the window the sample an output stands for sits (its time, its payload)
        self._anchor = 2 * HALF if self.causal else HALF
        self.reset()

    def reset(self) -> None:
        self._buf: deque[tuple[np.ndarray, np.ndarray | None, float | None]] = deque(maxlen=WINDOW_MA)
        self._n_raw = 0  # raw samples pushed
        self._n_pad = 0  # padded samples in the stream so far
        self._next = 0  # next raw centre index to emit (a multiple of STEP)

    def _append(self, item: tuple[np.ndarray, np.ndarray | None, float | None]) -> list[Frame20]:
        self._buf.append(item)
        self._n_pad += 1
        c = self._next
        if c < self._n_raw and c + 2 * HALF == self._n_pad - 1:
            items = list(self._buf)
            stack = [it[0] for it in items]
            acc = _window_mean(stack, self._anchor) if self.causal else _window_mean(stack)
            centre = items[self._anchor]
            self._next += STEP
            return [Frame20(index=c // STEP, t=centre[2], acc=acc, rest=centre[1])]
        return []

    def push(self, acc: np.ndarray, rest: np.ndarray | None = None, t: float | None = None) -> list[Frame20]:
        """Add one 60 Hz sample; returns the 20 Hz frames that became ready (0 or 1)."""
        item = (np.asarray(acc, dtype=np.float64), None if rest is None else np.asarray(rest), t)
        if self._n_raw == 0:
            for _ in range(self._anchor):
                self._buf.append(item)
                self._n_pad += 1
        self._n_raw += 1
        return self._append(item)

    def flush(self) -> list[Frame20]:
        """End of stream: pad with the last sample, emit the frames still pending (none
        when causal: each left with its own sample), reset."""
        out: list[Frame20] = []
        if self._n_raw:
            last = self._buf[-1]
            for _ in range(HALF):
                out += self._append(last)
        self.reset()
        return out


def slerp_unit(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The orientation between two samples at fraction ``w`` as ``to_grid`` takes it (slerp,
    renormalised); the live hub interpolates in batches with the same function."""
    return quat_normalize(quat_slerp(q0, q1, w))


def to_grid(
    t: np.ndarray,
    quat: np.ndarray,
    acc: np.ndarray,
    fps: float = 60.0,
    max_gap: float = 0.1,
    t0: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Resample irregularly timed device samples onto a regular `fps` grid.

    t: (N,) increasing sample times (s); quat: (N, ..., 4) (w,x,y,z); acc: (N, ..., 3).
    Returns (t_grid (M,), quat (M, ..., 4), acc (M, ..., 3), valid (M,) bool): slerp for
    orientation, linear for acceleration. A grid time whose bracketing samples are more
    than `max_gap` seconds apart (a dropout), or outside the sampled span, is missing:
    valid False, quat and acc NaN -- the poser then treats those features as unobserved.
    The grid starts at `t0` (default: first sample time rounded up to the grid, i.e. a
    multiple of 1/fps, so streams from several devices share one grid)."""
    t = np.asarray(t, dtype=np.float64)
    quat = np.asarray(quat, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    if t.ndim != 1 or t.shape[0] != quat.shape[0] or t.shape[0] != acc.shape[0]:
        raise ValueError("to_grid: t, quat and acc must have the same number of samples")
    if t.shape[0] < 1:
        raise ValueError("to_grid: no samples")
    if np.any(np.diff(t) <= 0):
        raise ValueError("to_grid: timestamps must be strictly increasing")
    start = np.ceil(t[0] * fps - 1e-9) / fps if t0 is None else float(t0)
    n = int(np.floor((t[-1] - start) * fps + 1e-9)) + 1
    tg = start + np.arange(max(n, 0)) / fps
    if tg.size == 0:
        return tg, quat[:0], acc[:0], np.zeros(0, bool)
    if t.shape[0] == 1:
        valid = np.abs(tg - t[0]) < 1e-9
        qg = np.broadcast_to(quat[:1], (tg.size,) + quat.shape[1:]).copy()
        ag = np.broadcast_to(acc[:1], (tg.size,) + acc.shape[1:]).copy()
    else:
        i1 = np.clip(np.searchsorted(t, tg, side="right"), 1, t.shape[0] - 1)
        i0 = i1 - 1
        dt = t[i1] - t[i0]
        w = np.clip((tg - t[i0]) / dt, 0.0, 1.0)
        inside = (tg >= t[0] - 1e-9) & (tg <= t[-1] + 1e-9)
        valid = inside & (dt <= max_gap + 1e-12)
        wq = w.reshape((-1,) + (1,) * (quat.ndim - 2))
        qg = slerp_unit(quat[i0], quat[i1], wq)
        wa = w.reshape((-1,) + (1,) * (acc.ndim - 1))
        ag = (1.0 - wa) * acc[i0] + wa * acc[i1]
    qg = np.where(valid.reshape((-1,) + (1,) * (qg.ndim - 1)), qg, np.nan)
    ag = np.where(valid.reshape((-1,) + (1,) * (ag.ndim - 1)), ag, np.nan)
    return tg, qg, ag, valid


def acc_filter_of(meta: dict | None) -> str:
    """The acceleration filter a model was trained on, from its file's metadata: "causal"
    or "centred". Files from before the causal option say nothing and are centred. The live
    resampler must filter the same way, or the model reads accelerations 83 ms late."""
    meta = meta or {}
    f = meta.get("acc_filter")
    if f is None:
        f = "causal" if (meta.get("train_config") or {}).get("causal") else "centred"
    if f not in ACC_FILTERS:
        raise ValueError(f"unknown acceleration filter {f!r} in the model file ({', '.join(ACC_FILTERS)})")
    return f


__all__ = ["moving_average", "downsample", "StreamingResampler", "Frame20", "to_grid", "slerp_unit", "HALF", "STEP",
           "ACC_FILTERS", "acc_filter_of"]
