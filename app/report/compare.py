"""Two sessions side by side: each figure before and after, their difference, and whether it exceeds
what the sensor sets let one tell apart.

A difference is marked when it exceeds both
- the expected error: the root sum of squares of the two sessions' expected errors of that figure for
  their sensor sets on synthesized walks (``confidence.Confidence.synthesized``, from
  ``benchmarks/report_gait_check.py``); a set with no such figure leaves it unmarked ("not known");
- twice the standard error of the difference of the two means (stride-to-stride variation): a change
  smaller than that is within what a next few strides would change anyway.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .analysis import GaitAnalysis
from .angles import ANGLES, RANGE_ANGLES
from .confidence import Confidence
from .events import SIDES

SIDE_NAMES = {"l": "left", "r": "right"}


@dataclass(frozen=True)
class Row:
    figure: str
    unit: str
    before: float | None
    after: float | None
    diff: float | None
    expected: float | None
    se2: float | None
    marked: bool

    def as_json(self) -> dict[str, Any]:
        r = lambda v: None if v is None else round(float(v), 4)  # noqa: E731
        return {"figure": self.figure, "unit": self.unit, "before": r(self.before), "after": r(self.after),
                "difference": r(self.diff), "expected_error": r(self.expected), "two_se": r(self.se2),
                "marked": self.marked}


def _stats(values) -> tuple[float | None, float | None, int]:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return None, None, 0
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else None, len(v)


def _expected(conf: Confidence, key: str, value: float | None, relative: bool) -> float | None:
    e = conf.synthesized.get(key)
    if e is None:
        return None
    if relative:
        return None if value is None else abs(value) * float(e) / 100.0
    return float(e)


def _row(figure: str, unit: str, a_vals, b_vals, key: str, ca: Confidence, cb: Confidence,
         relative: bool = False, centres: tuple[float | None, float | None] | None = None) -> Row:
    """a: before (the earlier session), b: after (this one). ``centres``: each session's figure where it is
    not the mean of the per-stride values (the cadence: 120 s over the mean stride time, as page one gives it,
    where the mean of per-stride cadences is larger); the per-stride values still give the spread."""
    ma, sa, na = _stats(a_vals)
    mb, sb, nb = _stats(b_vals)
    if centres is not None:
        ma = centres[0] if ma is not None else None
        mb = centres[1] if mb is not None else None
    diff = None if ma is None or mb is None else mb - ma
    ea, eb = _expected(ca, key, ma, relative), _expected(cb, key, mb, relative)
    expected = None if ea is None or eb is None else float(np.hypot(ea, eb))
    se2 = None
    if sa is not None and sb is not None:
        se2 = 2.0 * float(np.sqrt(sa * sa / na + sb * sb / nb))
    marked = bool(diff is not None and expected is not None and abs(diff) > expected
                  and (se2 is None or abs(diff) > se2))
    return Row(figure, unit, ma, mb, diff, expected, se2, marked)


def compare(before: GaitAnalysis, ca: Confidence, after: GaitAnalysis, cb: Confidence) -> list[Row]:
    rows: list[Row] = []
    wa, wb = before.summary.walking(), after.summary.walking()
    cad = lambda w: [120.0 / s.time_s for s in w]  # noqa: E731  per stride, so its SD is the strides'
    rows.append(_row("Cadence", "steps/min", cad(wa), cad(wb), "cadence_pct", ca, cb, relative=True,
                     centres=(before.summary.cadence_spm, after.summary.cadence_spm)))
    rows.append(_row("Walking speed", "m/s", [s.speed_mps for s in wa], [s.speed_mps for s in wb],
                     "speed_pct", ca, cb, relative=True))
    for side in SIDES:
        a, b = before.summary.walking(side), after.summary.walking(side)
        name = SIDE_NAMES[side]
        rows.append(_row(f"Stride time, {name}", "s", [s.time_s for s in a], [s.time_s for s in b],
                         "stride_time_s", ca, cb))
        rows.append(_row(f"Stance, {name}", "% of stride", [s.stance_pct for s in a], [s.stance_pct for s in b],
                         "stance_pct", ca, cb))
        rows.append(_row(f"Double support, {name}", "% of stride", [s.double_support_pct for s in a],
                         [s.double_support_pct for s in b], "stance_pct", ca, cb))
        rows.append(_row(f"Stride length, {name}", "m", [s.length_m for s in a], [s.length_m for s in b],
                         "speed_pct", ca, cb, relative=True))
    for angle in RANGE_ANGLES:
        for side in SIDES:
            rows.append(_row(f"{ANGLES[angle][0]} range, {SIDE_NAMES[side]}", "deg", before.ranges[side][angle],
                             after.ranges[side][angle], f"{angle}_range_deg", ca, cb))
    return rows
