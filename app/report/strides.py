"""Strides and their parameters, from the gait events of both feet and the root's path.

A stride of one foot runs from its foot strike to its next one. Per stride:
- ``time_s``; ``stance_pct`` (foot strike to foot off, % of the stride) and ``swing_pct`` (the rest);
- ``double_support_pct``: the time within the stride's stance in which the other foot is down too (both
  double supports of the stride), % of the stride;
- ``length_m``: the root's (pelvis joint's) horizontal travel from strike to strike, and ``speed_mps``
  = length / time;
- ``turn_deg``: the pelvis's change of heading over the stride.

Which strides count (``classify``): a stride is ``turning`` when the pelvis turned by more than
``TURN_DEG``; ``standing`` when it is too long or too slow to be a step of a walk (``MAX_STRIDE_S``,
``MIN_SPEED_MPS``) or its stance fills it (``MAX_STANCE_PCT``: shuffling on the spot); ``not walking``
when it is too quick or has too little stance for a walk (``MIN_STRIDE_S``, ``MIN_STANCE_PCT``: running,
hopping); the rest is ``walking``. Only walking strides enter the figures; the report says how many of
each kind it left out.

Per side: mean and SD over the walking strides; between sides the symmetry index
SI = 100 (L - R) / ((L + R) / 2) (Robinson et al. 1987), 0 when symmetric, positive when the left is
larger. Cadence: steps per minute, 120 / the mean walking stride time of both sides.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.body.conventions import yaw_of

from .events import SIDES, FootEvents, Stance

TURN_DEG = 20.0  # a straight stride turns the pelvis by a few degrees net; a turn in 2-4 strides, 45-90 each
MAX_STRIDE_S = 2.5  # a very slow walk's stride is ~1.6-2 s
MIN_STRIDE_S = 0.6  # ~200 steps/min: faster is a run or a hop
MIN_SPEED_MPS = 0.1  # slower: stepping on the spot
MAX_STANCE_PCT = 85.0  # walking 55-70 %
MIN_STANCE_PCT = 35.0  # walking 55-65 % (a speed-threshold contact reads ~50); a run ~30 %, a jog 2-5 % here
KINDS = ("walking", "turning", "standing", "not walking")
PARAMETERS = ("time_s", "stance_pct", "swing_pct", "double_support_pct", "length_m", "speed_mps")


@dataclass(frozen=True)
class Stride:
    side: str
    start: float
    off: float
    end: float
    time_s: float
    stance_pct: float
    swing_pct: float
    double_support_pct: float
    length_m: float
    speed_mps: float
    turn_deg: float
    kind: str = "walking"

    def value(self, name: str) -> float:
        return float(getattr(self, name))


def _interp_rows(t: np.ndarray, x: np.ndarray, at: float) -> np.ndarray:
    return np.array([np.interp(at, t, x[:, k]) for k in range(x.shape[1])])


def _overlap(a0: float, a1: float, stances: list[Stance]) -> float:
    return float(sum(max(0.0, min(a1, s.end) - max(a0, s.start)) for s in stances))


def classify(time_s: float, stance_pct: float, speed_mps: float, turn_deg: float) -> str:
    if abs(turn_deg) > TURN_DEG:
        return "turning"
    if time_s > MAX_STRIDE_S or speed_mps < MIN_SPEED_MPS or stance_pct > MAX_STANCE_PCT:
        return "standing"
    if time_s < MIN_STRIDE_S or stance_pct < MIN_STANCE_PCT:
        return "not walking"
    return "walking"


def strides_of(events: dict[str, FootEvents], t: np.ndarray, root: np.ndarray, pelvis_R: np.ndarray,
               gap_s: float | None = None) -> list[Stride]:
    """Every stride of both feet (time order per side). ``t``, ``root`` (T, 3), ``pelvis_R`` (T, 3, 3):
    the reconstruction's times, root path and pelvis orientations; a stride that spans a gap in ``t``
    longer than ``gap_s`` (default 2.5 median periods) is left out, its path unknown."""
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 2:
        return []
    gap_s = 2.5 * float(np.median(np.diff(t))) if gap_s is None else gap_s
    heading = np.degrees(np.unwrap(yaw_of(np.asarray(pelvis_R, dtype=np.float64))))
    root_xy = np.asarray(root, dtype=np.float64)[:, :2]
    gaps = [(float(a), float(b)) for a, b in zip(t[:-1], t[1:]) if b - a > gap_s]
    out: list[Stride] = []
    for side in SIDES:
        other = events["l" if side == "r" else "r"].stances
        st = events[side].stances
        for a, b in zip(st[:-1], st[1:]):
            if not (a.strike and a.off and b.strike):
                continue
            t0, t1 = a.start, b.start
            if t0 < t[0] or t1 > t[-1] or any(g0 < t1 and g1 > t0 for g0, g1 in gaps):
                continue
            dur = t1 - t0
            stance = 100.0 * (a.end - a.start) / dur
            ds = 100.0 * _overlap(a.start, a.end, other) / dur
            length = float(np.linalg.norm(_interp_rows(t, root_xy, t1) - _interp_rows(t, root_xy, t0)))
            turn = float(np.interp(t1, t, heading) - np.interp(t0, t, heading))
            speed = length / dur
            out.append(Stride(side, t0, a.end, t1, dur, stance, 100.0 - stance, ds, length, speed, turn,
                              classify(dur, stance, speed, turn)))
    return out


def match_strides(reference: list[Stride], found: list[Stride]) -> list[tuple[Stride, Stride]]:
    """The same strides in two analyses of one walk (a truth's and a report's, or two event sources):
    one-to-one (reference, found) pairs of the same foot whose strikes, at the start and at the end, each
    lie within half the reference stride's time of the reference's; the closest pairs (summed strike
    differences) first. Strides of every kind: the caller picks which count."""
    cands = []
    for i, a in enumerate(reference):
        for j, b in enumerate(found):
            if a.side != b.side:
                continue
            d0, d1 = abs(b.start - a.start), abs(b.end - a.end)
            if d0 < 0.5 * a.time_s and d1 < 0.5 * a.time_s:
                cands.append((d0 + d1, i, j))
    used_r: set[int] = set()
    used_f: set[int] = set()
    pairs = []
    for _, i, j in sorted(cands):
        if i not in used_r and j not in used_f:
            used_r.add(i)
            used_f.add(j)
            pairs.append((reference[i], found[j]))
    return pairs


def mean_sd(values) -> dict[str, float | None]:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return {"mean": None, "sd": None, "n": 0}
    return {"mean": float(v.mean()), "sd": float(v.std(ddof=1)) if len(v) > 1 else None, "n": int(len(v))}


def symmetry_index(left: float | None, right: float | None) -> float | None:
    """SI = 100 (L - R) / ((L + R) / 2); None when either is missing or their mean is ~0."""
    if left is None or right is None:
        return None
    m = 0.5 * (left + right)
    return None if abs(m) < 1e-9 else float(100.0 * (left - right) / m)


@dataclass
class StrideSummary:
    """The walking strides' figures per side, the symmetry between sides, and what was left out."""

    strides: list[Stride]
    per_side: dict[str, dict[str, dict]] = field(default_factory=dict)  # side -> parameter -> mean_sd
    symmetry: dict[str, float | None] = field(default_factory=dict)  # parameter -> SI
    cadence_spm: float | None = None
    excluded: dict[str, int] = field(default_factory=dict)  # kind -> count

    def walking(self, side: str | None = None) -> list[Stride]:
        return [s for s in self.strides if s.kind == "walking" and (side is None or s.side == side)]

    def count(self, side: str) -> int:
        return len(self.walking(side))


def summarize(strides: list[Stride]) -> StrideSummary:
    out = StrideSummary(strides)
    for side in SIDES:
        w = [s for s in strides if s.side == side and s.kind == "walking"]
        out.per_side[side] = {p: mean_sd([s.value(p) for s in w]) for p in PARAMETERS}
    for p in PARAMETERS:
        out.symmetry[p] = symmetry_index(out.per_side["l"][p]["mean"], out.per_side["r"][p]["mean"])
    times = [s.time_s for s in strides if s.kind == "walking"]
    out.cadence_spm = float(120.0 / np.mean(times)) if times else None
    out.excluded = {k: sum(1 for s in strides if s.kind == k) for k in KINDS if k != "walking"}
    return out


def cycle_curves(strides: list[Stride], t: np.ndarray, series: np.ndarray, points: int = 101) -> np.ndarray:
    """(N, points) of a (T,) angle series over each stride's cycle, 0-100 % from strike to strike,
    linearly interpolated between the reconstruction's frames."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(series, dtype=np.float64)
    pct = np.linspace(0.0, 1.0, points)
    if not strides:
        return np.zeros((0, points))
    return np.stack([np.interp(s.start + pct * s.time_s, t, y) for s in strides])


def _vertex(y0: float, y1: float, y2: float) -> float:
    """The extreme value of the parabola through three equally spaced samples whose middle one is the
    extreme of the three (the middle value itself when they are collinear); it lies within
    |y0 - y2| / 8 of the middle one."""
    den = y0 - 2.0 * y1 + y2
    return y1 if den == 0 else y1 - (y0 - y2) ** 2 / (8.0 * den)


def stride_ranges(strides: list[Stride], t: np.ndarray, series: np.ndarray) -> np.ndarray:
    """(N,) max - min of an angle over each stride: on the reconstruction's frames inside it and the
    values at its two ends, an extreme at a frame inside refined by the parabola through it and its two
    neighbours (a peak falls between 20 Hz frames: sampled, a truth's knee range reads ~1 deg, at most
    3 deg, short; docs/report.md)."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(series, dtype=np.float64)
    curves = cycle_curves(strides, t, y)
    if len(curves) == 0:
        return np.zeros(0)
    out = []
    for s, c in zip(strides, curves):
        idx = np.flatnonzero((t > s.start) & (t < s.end))
        lo, hi = float(min(c[0], c[-1])), float(max(c[0], c[-1]))
        if len(idx):
            v = y[idx]
            for k, better in ((int(idx[np.argmax(v)]), max), (int(idx[np.argmin(v)]), min)):
                peak = float(y[k])
                if 0 < k < len(y) - 1 and np.all(np.isfinite(y[k - 1: k + 2])):
                    y0, y2 = float(y[k - 1]), float(y[k + 1])
                    if better(y0, peak, y2) == peak:  # a peak of the three (not a slope into the next stride)
                        peak = better(peak, _vertex(y0, peak, y2))
                hi, lo = (max(hi, peak), lo) if better is max else (hi, min(lo, peak))
        out.append(hi - lo)
    return np.asarray(out)
