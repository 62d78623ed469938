"""The 60 Hz grid: each device's recent samples as rows of an array (``Ring``), and the
values of every site at a batch of grid times, held or interpolated (``grid_values``).

The default is the latest sample at or before a grid time, missing when older than
``staleness`` or inside a counter gap. To interpolate instead, the caller passes an
``Interpolation``: the hub then needs the sample *after* a grid time too (so it waits for
it), bridges gaps up to ``fill_gap`` and blends the two samples around each grid time with
the caller's ``slerp``. The drivers layer keeps no rotation maths of the model's own
(layering: drivers import nothing of ours), so this dataclass is the whole of what the hub
is given: the app passes inference's slerp, the one its offline resampler uses, and the
live grid matches the offline one (``tests/drivers/test_hub_interp.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from drivers.base import Sample

# (q0 (N,4), q1 (N,4), w (N,)) -> unit quaternions (N,4): q0 at w = 0, q1 at w = 1
Slerp = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
# (sample times (N,), quats (N,4), free acc (N,3), grid times (G,)) -> (quats (G,4), acc (G,3), valid (G,))
StreamResampler = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                           tuple[np.ndarray, np.ndarray, np.ndarray]]
# per site: [(start, end)] session times between which packets were lost
Gaps = Sequence[tuple[float, float]]


@dataclass(frozen=True)
class Interpolation:
    """How the hub interpolates to the grid (the centred latency mode, docs/latency.md).

    slerp: blends two orientations; the hub finds each grid time's pair of samples for
    every site in one comparison and calls it once for all of them. max_gap: the widest
    pair (s) interpolated across. per_stream: when given, called for each site instead of
    the batch -- the reference the batch is tested against (``tests/drivers/test_hub_interp.py``)
    and measured against (``benchmarks/bench_drivers.py --interpolation``)."""

    slerp: Slerp | None = None
    max_gap: float = 0.1
    per_stream: StreamResampler | None = None

    def __post_init__(self) -> None:
        if self.slerp is None and self.per_stream is None:
            raise ValueError("Interpolation needs a slerp (or a per-stream resampler)")


class Ring:
    """Recent samples of one device as rows of a float array: t, quat(4), free_acc(3),
    acc(3), gyro(3), packet counter, position(3) (a tracked device's ``extra["position"]``);
    NaN where the device does not report a quantity. Rows are
    contiguous (the buffer is twice the capacity and slides back when full), so the
    grid code works on array views without per-sample Python."""

    COLS = 18
    COUNTER = 14
    POSITION = slice(15, 18)

    def __init__(self, capacity: int = 512) -> None:
        self.cap = capacity
        self.buf = np.full((2 * capacity, self.COLS), np.nan)
        self.start = 0
        self.end = 0
        self.has = {"quat": False, "free_acc": False, "acc": False, "gyro": False, "position": False}

    def __len__(self) -> int:
        return self.end - self.start

    _FIELDS = (("quat", 1, 5), ("free_acc", 5, 8), ("acc", 8, 11), ("gyro", 11, 14))

    def append(self, t: float, s: Sample) -> None:
        self.extend([t], [s])

    def extend(self, ts: list[float], samples: list[Sample]) -> None:
        """Write a batch of samples as rows, one numpy assignment per quantity."""
        n = len(samples)
        if n > self.cap:
            ts, samples, n = ts[-self.cap :], samples[-self.cap :], self.cap
        if self.end + n > self.buf.shape[0]:
            keep = min(len(self), self.cap - n)
            self.buf[:keep] = self.buf[self.end - keep : self.end]
            self.start, self.end = 0, keep
        block = self.buf[self.end : self.end + n]
        block[:, 0] = ts
        block[:, self.COUNTER] = [np.nan if s.counter is None else s.counter for s in samples]
        for name, a, b in self._FIELDS:
            vals = [getattr(s, name) for s in samples]
            if all(v is not None for v in vals):
                block[:, a:b] = vals
                self.has[name] = True
            else:
                for r, v in zip(block, vals, strict=True):
                    if v is None:
                        r[a:b] = np.nan
                    else:
                        r[a:b] = v
                        self.has[name] = True
        pos = [s.extra.get("position") if s.extra else None for s in samples]
        if any(p is not None for p in pos):
            block[:, self.POSITION] = [np.full(3, np.nan) if p is None else p for p in pos]
            self.has["position"] = True
        else:
            block[:, self.POSITION] = np.nan
        self.end += n
        if len(self) > self.cap:
            self.start = self.end - self.cap

    def rows(self, t_from: float) -> np.ndarray:
        """Rows with time >= t_from, plus the one before (the sample held at t_from)."""
        view = self.buf[self.start : self.end]
        i = int(np.searchsorted(view[:, 0], t_from, side="left"))
        return view[max(0, i - 1) :]

    def last(self, n: int) -> np.ndarray:
        """The newest ``n`` rows, NaN-padded at the front when fewer are held."""
        if len(self) >= n:
            return self.buf[self.end - n : self.end]
        out = np.full((n, self.COLS), np.nan)
        if len(self):
            out[n - len(self) :] = self.buf[self.start : self.end]
        return out

    def last_t(self) -> float | None:
        return float(self.buf[self.end - 1, 0]) if len(self) else None



def stack_windows(rings: Sequence[Ring], t0: float) -> np.ndarray:
    """The last ``W`` rows of every ring as one (S, W, COLS) array (NaN-padded at the
    front), ``W`` doubling from 16 until every window reaches back to ``t0`` (a few rows in
    the steady state) or holds its whole ring."""
    S, W = len(rings), 16
    while True:
        block = np.stack([r.last(W) for r in rings]) if S else np.empty((0, W, Ring.COLS))
        first_t = block[:, 0, 0]  # NaN where a ring holds fewer than W rows
        short = ~(first_t <= t0) & np.array([len(r) > W for r in rings], bool)
        if not short.any() or W >= rings[0].cap:
            return block
        W *= 2


def per_stream(rings: Sequence[Ring], gaps: Sequence[Gaps], grid: np.ndarray, staleness: float, fill_gap: float,
               resample: StreamResampler | None) -> tuple[np.ndarray, ...]:
    """Grid values site by site, each site's samples through ``resample`` (None: held):
    the reference ``batched`` is tested against. Returns (quat, free, acc, gyro, present,
    newest) over (grid time, site), newest being the session time and packet counter of the
    newest sample that went into each value."""
    G, S = grid.size, len(rings)
    quat = np.full((G, S, 4), np.nan)
    free = np.full((G, S, 3), np.nan)
    acc = np.full((G, S, 3), np.nan)
    gyro = np.full((G, S, 3), np.nan)
    present = np.zeros((G, S), bool)
    newest = np.full((G, S, 2), np.nan)  # session time, packet counter
    for k, ring in enumerate(rings):
        if not len(ring):
            continue
        rows = ring.rows(grid[0] - 0.5)
        ts = rows[:, 0]
        idx = np.searchsorted(ts, grid, side="right") - 1
        ii = np.maximum(idx, 0)
        interp = resample is not None and ring.has["quat"]
        # interpolating, a grid time only needs samples on both sides no more than
        # fill_gap apart (the resampler checks its own max_gap too)
        reach = max(staleness, fill_gap) if interp else staleness
        ok = (idx >= 0) & (grid - ts[ii] <= reach)
        for a, b in gaps[k]:
            if not interp or b - a > fill_gap:
                ok &= ~((grid > a) & (grid < b))
        if interp:
            if ts.size >= 2:
                fa = rows[:, 5:8] if ring.has["free_acc"] else np.zeros((ts.size, 3))
                q_g, a_g, v_g = resample(ts, rows[:, 1:5], fa, grid)  # type: ignore[misc]
                ok &= np.asarray(v_g, bool)
                quat[:, k] = q_g
                if ring.has["free_acc"]:
                    free[:, k] = a_g
            else:
                ok[:] = False
        else:
            quat[:, k] = rows[ii, 1:5]
            free[:, k] = rows[ii, 5:8]
        acc[:, k] = rows[ii, 8:11]
        gyro[:, k] = rows[ii, 11:14]
        present[:, k] = ok
        # interpolation reads the sample after the grid time too (and so waits for it)
        last = np.minimum(idx + 1, ts.size - 1) if interp else ii
        newest[:, k, 0] = ts[last]
        newest[:, k, 1] = rows[last, Ring.COUNTER]
    for arr in (quat, free, acc, gyro):
        arr[~present] = np.nan
    newest[~present] = np.nan
    return quat, free, acc, gyro, present, newest


def batched(rings: Sequence[Ring], gaps: Sequence[Gaps], grid: np.ndarray, staleness: float, fill_gap: float,
            interpolation: Interpolation | None) -> tuple[np.ndarray, ...]:
    """``per_stream`` for every site at once: the last rows of every ring stacked into one
    (S, W, COLS) array (``stack_windows``), each grid time's held row and bracketing pair
    of samples found in one comparison, and with an ``interpolation`` one batched slerp
    over the (site, grid time) pairs of the sites that send orientation (None: every site
    held). Per poll a fixed handful of numpy calls instead of a full resampler per site:
    with seven devices at 60 polls a second those calls held the interpreter lock for a
    third of a capture process's time, beside the drivers and the model
    (``docs/pipeline.md``). Same values as ``per_stream`` given inference's ``to_grid``
    (``tests/drivers/test_hub_interp.py``)."""
    S = len(rings)
    rs = interpolation
    block = stack_windows(rings, grid[0])
    W = block.shape[1]
    ts = block[:, :, 0]
    ks = np.arange(S)[:, None]
    after = (ts[:, :, None] > grid[None, None, :]).sum(axis=1)  # (S, G); NaN compares False
    idx = W - 1 - after
    ii = np.maximum(idx, 0)
    interp = np.array([rs is not None and r.has["quat"] for r in rings], bool)
    has_free = np.array([r.has["free_acc"] for r in rings], bool)
    reach = np.where(interp, max(staleness, fill_gap), staleness)[:, None]
    ok = (idx >= 0) & (grid[None, :] - ts[ks, ii] <= reach)  # NaN (no row) -> False
    for k in range(S):
        for a, b in gaps[k]:
            if not interp[k] or b - a > fill_gap:
                ok[k] &= ~((grid > a) & (grid < b))
    # the pair around each grid time, as to_grid picks it (the last pair at the newest sample)
    i1 = np.clip(idx + 1, 1, W - 1)
    i0 = i1 - 1
    t0, t1 = ts[ks, i0], ts[ks, i1]
    dt = t1 - t0
    if rs is not None:
        with np.errstate(invalid="ignore"):
            pair_ok = ((dt <= rs.max_gap + 1e-12) & (grid[None, :] <= ts[:, -1:] + 1e-9)
                       & (t0 <= grid[None, :] + 1e-9))
        ok &= ~interp[:, None] | pair_ok
    held = block[ks, ii]  # (S, G, COLS)
    quat = held[:, :, 1:5].copy()
    free = held[:, :, 5:8].copy()
    sel = ok & interp[:, None]
    if rs is not None and rs.slerp is not None and sel.any():
        ka, ga = np.nonzero(sel)
        a, b = i0[ka, ga], i1[ka, ga]
        w = np.clip((grid[ga] - t0[ka, ga]) / dt[ka, ga], 0.0, 1.0)
        quat[ka, ga] = rs.slerp(block[ka, a, 1:5], block[ka, b, 1:5], w)
        lerp = (1.0 - w)[:, None] * block[ka, a, 5:8] + w[:, None] * block[ka, b, 5:8]
        free[ka, ga] = np.where(has_free[ka][:, None], lerp, np.nan)
    free[interp & ~has_free] = np.nan
    # interpolation reads the sample after the grid time too (and so waits for it)
    last = np.where(interp[:, None], np.minimum(idx + 1, W - 1), ii)
    newest = np.stack([ts[ks, last], block[ks, last, Ring.COUNTER]], axis=-1)
    out = [x.transpose(1, 0, 2).copy() for x in (quat, free, held[:, :, 8:11], held[:, :, 11:14], newest)]
    present = ok.T.copy()
    for arr in out:
        arr[~present] = np.nan
    quat, free, acc, gyro, newest = out
    return quat, free, acc, gyro, present, newest


def positions(rings: Sequence[Ring], grid: np.ndarray, present: np.ndarray,
              interpolation: Interpolation | None) -> np.ndarray:
    """(G, S, 3) positions on the grid of the rings that carry them (a tracked device's
    sites), NaN elsewhere and where ``present`` (G, S) is False: held as the other channels
    are, or with an ``interpolation`` blended linearly between the pair of samples around
    each grid time that ``batched`` takes for the free acceleration (the same pair and
    weight), so a position and the orientation beside it stand for one instant."""
    G, S = grid.size, len(rings)
    out = np.full((G, S, 3), np.nan)
    for k, ring in enumerate(rings):
        if not ring.has["position"] or not len(ring) or not present[:, k].any():
            continue
        rows = ring.rows(grid[0] - 0.5)
        ts = rows[:, 0]
        n = ts.size
        idx = np.searchsorted(ts, grid, side="right") - 1
        if interpolation is not None and ring.has["quat"] and n >= 2:
            i1 = np.clip(idx + 1, 1, n - 1)
            i0 = i1 - 1
            dt = ts[i1] - ts[i0]
            w = np.clip((grid - ts[i0]) / np.where(dt > 0, dt, 1.0), 0.0, 1.0)[:, None]
            p = (1.0 - w) * rows[i0, Ring.POSITION] + w * rows[i1, Ring.POSITION]
        else:
            p = rows[np.maximum(idx, 0), Ring.POSITION]
        out[:, k] = np.where(present[:, k, None], p, np.nan)
    return out
