"""How the reference and the reconstruction are put on one clock and one heading.

Time: the offset is the lag that maximises the correlation of the joint flexion angles
both sides have (knees, hips, elbows; ``kinematics.paired_joint_angles``), averaged over
the joints: angles do not depend on heading, position or the systems' world frames, so
the clock is found before anything else is known. Every lag at which the two overlap by
at least half the shorter is scored at once: both sides on a ``GRID_S`` grid, the
Pearson correlation over each lag's overlap from six FFT cross-correlations (of the
validity masks, the values, their squares and products: N log N, not lags x N), then a
fine search (2 ms) around the best and a parabola through the top three.

It says when it may be wrong (``Alignment.warnings``) and shows the candidates: a peak
below ``LOW_CORRELATION``, or another peak at least ``MIN_PEAK_SEPARATION_S`` away within
``CLOSE_PEAK`` of it (a steady walk or a treadmill repeats itself every stride, and an
offset one stride off would give errors that look normal). ``--offset`` settles it.

Heading: one rotation about the vertical for the whole trial, the least-squares one over
the segments both sides have: orientations when the reference has them
(sum of R_ref R_rec^T), else segment directions (sum of d_ref d_rec^T); the yaw of the
best Z rotation of a 3x3 sum M is ``conventions.yaw_of(M)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import correlate

from inference.body.conventions import yaw_of

MIN_OVERLAP_FRACTION = 0.5
MIN_OVERLAP_S = 2.0
GRID_S = 0.01  # the FFT search's grid
COARSE_STEP_S = 0.05  # the fine search spans two of these either side of the best grid lag
FINE_STEP_S = 0.002
LOW_CORRELATION = 0.8  # below it the offset is reported with a warning
CLOSE_PEAK = 0.05  # a second peak within this much correlation of the best is a rival
MIN_PEAK_SEPARATION_S = 0.3  # peaks closer than this are one peak
N_CANDIDATES = 3  # peaks always shown; every other one within CLOSE_PEAK of the best too
MAX_CANDIDATES = 12


@dataclass
class Alignment:
    """time_offset_s: reference clock minus recording clock (a reference frame at time s
    shows what the recording has at s - offset); correlation: the mean over ``joints`` of
    the angles' correlation at that offset; heading_deg: the yaw that turns the
    recording's world into the reference's; candidates: the best peaks of the offset
    search (the chosen one first); warnings: why the offset may be wrong."""

    time_offset_s: float
    correlation: float | None
    joints: list[str]
    heading_deg: float
    heading_from: str
    time_given: bool = False
    heading_given: bool = False
    candidates: list[tuple[float, float]] = field(default_factory=list)  # (offset s, correlation), best first
    warnings: list[str] = field(default_factory=list)


def _standardise(x: np.ndarray) -> np.ndarray:
    ok = np.isfinite(x)
    if ok.sum() < 3:
        return np.full_like(x, np.nan)
    s = np.nanstd(x)
    return (x - np.nanmean(x)) / (s if s > 1e-9 else 1.0)


def correlation_at(lag: float, t_rec: np.ndarray, rec: dict[str, np.ndarray], t_ref: np.ndarray,
                   ref: dict[str, np.ndarray], min_overlap: float) -> float:
    """Mean over the joints of the Pearson correlation between the recording's angles and
    the reference's at time t_rec + lag (linear interpolation), over their overlap."""
    tq = t_rec + lag
    inside = (tq >= t_ref[0]) & (tq <= t_ref[-1])
    if inside.sum() < 3 or (tq[inside][-1] - tq[inside][0]) < min_overlap:
        return -np.inf
    rs = []
    for j in rec:
        a = rec[j][inside]
        b = np.interp(tq[inside], t_ref, ref[j])
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.sum() < 3:
            continue
        a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
        den = np.sqrt((a * a).sum() * (b * b).sum())
        if den > 1e-12:
            rs.append(float((a * b).sum() / den))
    return float(np.mean(rs)) if rs else -np.inf


def _on_grid(t: np.ndarray, x: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """x(t) linearly interpolated at ``grid``, NaN where x is NaN at either neighbour."""
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.full(len(grid), np.nan)
    y = np.interp(grid, t[ok], x[ok])
    # a gap in x stays a gap: NaN where the nearest sample is missing
    k = np.clip(np.searchsorted(t, grid), 0, len(t) - 1)
    y[~ok[k]] = np.nan
    return y


def correlation_curve(t_rec: np.ndarray, rec: dict[str, np.ndarray], t_ref: np.ndarray, ref: dict[str, np.ndarray],
                      min_overlap: float, step: float = GRID_S) -> tuple[np.ndarray, np.ndarray]:
    """(lags (L,), mean over the joints of the Pearson correlation at each lag (L,), -inf
    where the overlap is shorter than ``min_overlap``): every lag on a ``step`` grid, each
    joint's correlation over its overlap from FFT cross-correlations (module docstring)."""
    g_rec = t_rec[0] + np.arange(int(np.floor((t_rec[-1] - t_rec[0]) / step)) + 1) * step
    g_ref = t_ref[0] + np.arange(int(np.floor((t_ref[-1] - t_ref[0]) / step)) + 1) * step
    # lag of correlate(ref, rec)[m]: ref grid start - rec grid start + (m - (len(rec) - 1)) * step
    lags = (t_ref[0] - t_rec[0]) + (np.arange(len(g_rec) + len(g_ref) - 1) - (len(g_rec) - 1)) * step
    total = np.zeros(len(lags))
    count = np.zeros(len(lags))
    enough = np.zeros(len(lags), bool)
    min_n = max(3, int(np.ceil(min_overlap / step)))
    for j in rec:
        x, y = _on_grid(t_rec, rec[j], g_rec), _on_grid(t_ref, ref[j], g_ref)
        mx, my = np.isfinite(x).astype(float), np.isfinite(y).astype(float)
        x, y = np.where(mx > 0, x, 0.0), np.where(my > 0, y, 0.0)
        x = x - x[mx > 0].mean() if mx.any() else x  # centred: the sums stay well conditioned
        y = y - y[my > 0].mean() if my.any() else y

        def xc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return correlate(b, a, mode="full", method="fft")

        n = np.rint(xc(mx, my))
        sx, sy, sxy = xc(x, my), xc(mx, y), xc(x, y)
        sxx, syy = xc(x * x, my), xc(mx, y * y)
        with np.errstate(invalid="ignore", divide="ignore"):
            cov = sxy - sx * sy / n
            var = (sxx - sx * sx / n) * (syy - sy * sy / n)
            r = cov / np.sqrt(var)
        good = (n >= min_n) & np.isfinite(r) & (var > 1e-12 * np.maximum(n, 1) ** 2)
        total[good] += np.clip(r[good], -1.0, 1.0)
        count[good] += 1
        enough |= n >= min_n
    with np.errstate(invalid="ignore", divide="ignore"):
        score = np.where(count > 0, total / np.maximum(count, 1), -np.inf)
    return lags, np.where(enough, score, -np.inf)


def peaks(lags: np.ndarray, score: np.ndarray, separation: float = MIN_PEAK_SEPARATION_S,
          n: int = MAX_CANDIDATES) -> list[int]:
    """Indices of the (at most ``n``) highest local maxima of ``score``, best first, no two
    closer than ``separation`` s."""
    s = np.where(np.isfinite(score), score, -np.inf)
    if len(s) < 3:
        return [int(np.argmax(s))] if len(s) else []
    local = np.flatnonzero((s[1:-1] >= s[:-2]) & (s[1:-1] >= s[2:]) & np.isfinite(s[1:-1])) + 1
    ends = [k for k in (0, len(s) - 1) if np.isfinite(s[k])]
    order = sorted([*local, *ends], key=lambda k: -s[k])
    out: list[int] = []
    for k in order:
        if all(abs(lags[k] - lags[q]) >= separation for q in out):
            out.append(int(k))
        if len(out) == n:
            break
    return out


def _refine(g: float, t_rec, rec, t_ref, ref, min_overlap) -> tuple[float, float]:
    fine = np.arange(g - 2 * COARSE_STEP_S, g + 2 * COARSE_STEP_S + 1e-9, FINE_STEP_S)
    fs = np.array([correlation_at(x, t_rec, rec, t_ref, ref, min_overlap) for x in fine])
    k = int(np.argmax(fs))
    lag = float(fine[k])
    if 0 < k < len(fine) - 1 and np.all(np.isfinite(fs[k - 1:k + 2])):
        a, b, c = fs[k - 1:k + 2]
        den = a - 2 * b + c
        if den < 0:
            lag += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) * FINE_STEP_S
    return lag, float(fs[k])


def find_time_offset(t_rec: np.ndarray, rec: dict[str, np.ndarray], t_ref: np.ndarray,
                     ref: dict[str, np.ndarray]) -> tuple[float, float, list[str]]:
    """(offset, correlation, joints used): module docstring."""
    lag, corr, joints, _, _ = search_time_offset(t_rec, rec, t_ref, ref)
    return lag, corr, joints


def search_time_offset(t_rec: np.ndarray, rec: dict[str, np.ndarray], t_ref: np.ndarray, ref: dict[str, np.ndarray]
                       ) -> tuple[float, float, list[str], list[tuple[float, float]], list[str]]:
    """(offset, correlation, joints used, candidates (offset, correlation) best first,
    warnings): module docstring."""
    joints = sorted(set(rec) & set(ref))
    if not joints:
        raise ValueError("the reference and the reconstruction share no joint angle (knee, hip, elbow) to find "
                         "the time offset from; give it with --offset")
    rec = {j: rec[j] for j in joints}
    ref = {j: ref[j] for j in joints}
    dur_rec, dur_ref = t_rec[-1] - t_rec[0], t_ref[-1] - t_ref[0]
    min_overlap = max(min(MIN_OVERLAP_S, 0.9 * min(dur_rec, dur_ref)), MIN_OVERLAP_FRACTION * min(dur_rec, dur_ref))
    lags, score = correlation_curve(t_rec, rec, t_ref, ref, min_overlap)
    if not np.isfinite(score).any():
        raise ValueError("the reference and the recording never overlap long enough to be compared "
                         f"(at least {min_overlap:.1f} s)")
    top = peaks(lags, score)
    top = [k for i, k in enumerate(top) if i < N_CANDIDATES or score[k] >= score[top[0]] - CLOSE_PEAK]
    cands = [_refine(float(lags[k]), t_rec, rec, t_ref, ref, min_overlap) for k in top]
    cands.sort(key=lambda c: -c[1])
    lag, corr = cands[0]
    warnings = []
    if corr < LOW_CORRELATION:
        warnings.append(f"time offset {lag:+.3f} s has a low correlation ({corr:.2f} < {LOW_CORRELATION}): the "
                        "reference may not show the same trial; check it, or give the offset with --offset")
    rivals = [c for c in cands[1:] if c[1] >= corr - CLOSE_PEAK]
    if rivals:
        alts = ", ".join(f"{o:+.3f} s (correlation {r:.3f})" for o, r in rivals)
        warnings.append(f"time offset {lag:+.3f} s (correlation {corr:.3f}) has a rival: {alts}; a steady walk "
                        "repeats itself every stride, so either may be the true one; give it with --offset")
    return lag, corr, joints, cands, warnings


def heading_from_rotations(R_rec: np.ndarray, R_ref: np.ndarray) -> float:
    """Yaw (rad) turning R_rec (T, S, 3, 3) onto R_ref, least squares over frames and segments."""
    M = np.einsum("tsij,tskj->ik", R_ref, R_rec)
    return float(yaw_of(M))


def heading_from_directions(d_rec: dict[str, np.ndarray], d_ref: dict[str, np.ndarray]) -> float:
    """Yaw (rad) turning the recording's segment directions onto the reference's."""
    M = np.zeros((3, 3))
    for s in set(d_rec) & set(d_ref):
        a, b = d_ref[s], d_rec[s]
        ok = np.all(np.isfinite(a), axis=-1) & np.all(np.isfinite(b), axis=-1)
        M += a[ok].T @ b[ok]
    if not np.any(M):
        raise ValueError("the reference and the reconstruction share no segment to find the heading from; "
                         "give it with --heading")
    return float(yaw_of(M))


__all__ = ["Alignment", "find_time_offset", "search_time_offset", "correlation_curve", "peaks", "correlation_at",
           "heading_from_rotations", "heading_from_directions"]
