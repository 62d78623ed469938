"""Whether a confidence spread predicts the error: rank correlation and band coverage.

A spread is only useful to a clinician if (a) a larger spread goes with a larger error
(ranks: Spearman, which asks for no particular scale) and (b) it can be turned into a
band the error falls inside as often as the band claims. The bands are the spread times
a factor, with a floor for what the spread cannot see (the sensor's own orientation
error on a measured segment, whose spread is 0): radius = max(floor, scale * spread).
Floor and scale are fit per coverage level on clips other than the ones scored
(``fit_bands``), so a reported coverage is a prediction, not a fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import spearmanr

from inference.body.rotations import matrix_angle_between

LEVELS: tuple[float, ...] = (0.5, 0.9)


def segment_errors_deg(R_pred: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """(T, 24) geodesic angle (deg) of each segment's global orientation from the truth."""
    return np.rad2deg(matrix_angle_between(np.asarray(R_pred, np.float64), np.asarray(R_true, np.float64)))


def root_errors_m(root_pred: np.ndarray, root_true: np.ndarray, frames: int) -> np.ndarray:
    """(T,) how far the root is off, as the root spread measures it: the height error and
    the error of the horizontal displacement over the last ``frames`` frames (NaN before)."""
    root_pred, root_true = np.asarray(root_pred, np.float64), np.asarray(root_true, np.float64)
    dz = root_pred[:, 2] - root_true[:, 2]
    out = np.full(len(dz), np.nan)
    if len(dz) > frames:
        d = (root_pred[frames:, :2] - root_pred[:-frames, :2]) - (root_true[frames:, :2] - root_true[:-frames, :2])
        out[frames:] = np.sqrt(dz[frames:] ** 2 + (d ** 2).sum(axis=-1))
    return out


def spearman(x: np.ndarray, y: np.ndarray) -> float | None:
    """Rank correlation of paired samples (NaN pairs dropped); None when either side is
    constant or fewer than 3 pairs remain."""
    x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return None
    return float(spearmanr(x, y).statistic)


@dataclass(frozen=True)
class Band:
    """radius = max(floor, scale * spread) covers the error ``level`` of the time."""

    level: float
    floor: float
    scale: float

    def radius(self, spread: np.ndarray) -> np.ndarray:
        return np.maximum(self.floor, self.scale * np.asarray(spread, np.float64))


def fit_bands(errors: np.ndarray, spreads: np.ndarray, levels: Sequence[float] = LEVELS) -> list[Band]:
    """Per level: the floor is that quantile of the errors where the spread is 0 (what a
    measurement leaves), the scale the smallest that makes the band cover ``level`` of
    the pairs with a spread (bisection on the coverage, which grows with the scale)."""
    e, s = np.asarray(errors, np.float64).ravel(), np.asarray(spreads, np.float64).ravel()
    ok = np.isfinite(e) & np.isfinite(s)
    e, s = e[ok], s[ok]
    zero, pos = s <= 0, s > 0
    bands = []
    for q in levels:
        floor = float(np.quantile(e[zero], q)) if zero.any() else 0.0
        if not pos.any():
            bands.append(Band(q, floor, 0.0))
            continue
        lo, hi = 0.0, max(1.0, float(np.max(e[pos] / s[pos])))
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if np.mean(e[pos] <= np.maximum(floor, mid * s[pos])) >= q:
                hi = mid
            else:
                lo = mid
        bands.append(Band(q, floor, hi))
    return bands


def coverage(errors: np.ndarray, spreads: np.ndarray, band: Band) -> float | None:
    """Share of the pairs whose error lies inside the band (None without pairs)."""
    e, s = np.asarray(errors, np.float64).ravel(), np.asarray(spreads, np.float64).ravel()
    ok = np.isfinite(e) & np.isfinite(s)
    if not ok.any():
        return None
    return float(np.mean(e[ok] <= band.radius(s[ok])))


def calibration_table(errors: np.ndarray, spreads: np.ndarray, names: Sequence[str], bands: Sequence[Band],
                      segments: Sequence[int]) -> dict:
    """The figures of one sensor set: errors and spreads (T, S) pooled over clips, per
    column in ``segments``: mean spread and error, Spearman over frames (None where the
    spread never varies, e.g. a measured segment), coverage per band; pooled over those
    columns: Spearman over all (frame, segment) pairs, Spearman of the per-segment means,
    and coverage per band."""
    cols = list(segments)
    e, s = np.asarray(errors, np.float64)[:, cols], np.asarray(spreads, np.float64)[:, cols]
    rows = {}
    for k, c in enumerate(cols):
        rows[names[c]] = {
            "spread": _mean(s[:, k]), "error": _mean(e[:, k]), "spearman": spearman(s[:, k], e[:, k]),
            **{f"inside_{round(100 * b.level)}": coverage(e[:, k], s[:, k], b) for b in bands},
        }
    means = [(r["spread"], r["error"]) for r in rows.values() if r["spread"] is not None]
    return {
        "segments": rows,
        "spearman_pooled": spearman(s, e),
        "spearman_segment_means": spearman([m[0] for m in means], [m[1] for m in means]),
        **{f"inside_{round(100 * b.level)}": coverage(e, s, b) for b in bands},
        "bands": [asdict(b) for b in bands],
    }


def _mean(x: np.ndarray) -> float | None:
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else None


__all__ = ["LEVELS", "segment_errors_deg", "root_errors_m", "spearman", "Band", "fit_bands", "coverage",
           "calibration_table"]
