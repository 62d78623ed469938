"""The foot sensors' own word on the strides: where a foot sensor is worn, its stillness (the foot flat on
the ground, between foot strike and foot off) checks the events the report found.

A foot sensor is still (``still_periods``) while its angular rate stays under ``STILL_GYRO`` and its
specific force within ``STILL_ACC`` of gravity over ``WINDOW_S`` (a zero-velocity detector, as
inertial foot navigation uses), for at least ``MIN_STILL_S``. Each still period that lies between two
moves of the foot is one step of that foot (``steps``): a found stance ``contains`` it when it covers
most of it. ``check`` tables, per foot: the steps, how many a found stance covers, how many found
stances hold no still period, the found strike's lead before the foot goes still and the found foot
off's lag after it moves again (median, ms), and the stride times from one still start to the next
against the found ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .events import FootEvents

STILL_GYRO = 1.0  # rad/s (57 deg/s): a foot rolling over heel or toe turns faster, a flat foot hardly at all
STILL_ACC = 2.0  # m/s^2 about g
WINDOW_S = 0.1
MIN_STILL_S = 0.1
COVER = 0.5  # share of a still period a found stance must cover


def still_periods(t: np.ndarray, gyro: np.ndarray, acc: np.ndarray, present: np.ndarray | None = None
                  ) -> list[tuple[float, float]]:
    t = np.asarray(t, dtype=np.float64)
    w = np.linalg.norm(np.asarray(gyro, dtype=np.float64), axis=1)
    a = np.abs(np.linalg.norm(np.asarray(acc, dtype=np.float64), axis=1) - 9.81)
    ok = (w < STILL_GYRO) & (a < STILL_ACC)
    if present is not None:
        ok &= np.asarray(present, dtype=bool)
    ok &= np.isfinite(w) & np.isfinite(a)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    half = max(1, int(round(WINDOW_S / dt / 2)))
    # still over the whole window round each sample: the minimum of ok over it
    pad = np.concatenate([np.zeros(half, bool), ok, np.zeros(half, bool)])
    win = np.ones(len(ok), dtype=bool)
    for k in range(2 * half + 1):
        win &= pad[k: k + len(ok)]
    out = []
    i = 0
    while i < len(win):
        if not win[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(win) and win[j + 1]:
            j += 1
        start, end = float(t[max(i - half, 0)]), float(t[min(j + half, len(t) - 1)])
        if end - start >= MIN_STILL_S:
            out.append((start, end))
        i = j + 1
    return out


def steps(periods: list[tuple[float, float]], t0: float, t1: float) -> list[tuple[float, float]]:
    """Still periods with the foot moving before and after them inside [t0, t1] (not the stands at the
    ends of the data)."""
    return [(a, b) for a, b in periods if a > t0 + 1e-9 and b < t1 - 1e-9]


def _covering(stance_list, a: float, b: float):
    for s in stance_list:
        if min(s.end, b) - max(s.start, a) >= COVER * (b - a):
            return s
    return None


def check(events: FootEvents, periods: list[tuple[float, float]], t0: float, t1: float) -> dict[str, Any]:
    """One foot: the found events against its sensor's still periods (module docstring)."""
    st = steps(periods, t0, t1)
    found = [s for s in events.stances if s.start > t0 and s.end < t1]
    covered, lead, lag = 0, [], []
    for a, b in st:
        s = _covering(found, a, b)
        if s is None:
            continue
        covered += 1
        if s.strike:
            lead.append(a - s.start)
        if s.off:
            lag.append(s.end - b)
    empty = sum(1 for s in found if not any(min(s.end, b) - max(s.start, a) > 0 for a, b in st))
    still_strides = np.diff([a for a, _ in st])
    found_strikes = np.array([s.start for s in found if s.strike])
    pairs = []
    for k in range(len(st) - 1):  # a stride of the sensor's and the found one starting nearest to it
        if len(found_strikes) < 2:
            break
        i = int(np.argmin(np.abs(found_strikes - st[k][0])))
        if i + 1 < len(found_strikes):
            pairs.append((float(still_strides[k]), float(found_strikes[i + 1] - found_strikes[i])))
    med = lambda v: None if not v else round(1000.0 * float(np.median(v)), 1)  # noqa: E731
    return {"still_steps": len(st), "covered": covered, "found_stances": len(found), "found_without_still": empty,
            "strike_lead_ms": med(lead), "off_lag_ms": med(lag),
            "stride_time_diff_ms": None if not pairs else round(1000.0 * float(np.median([abs(b - a)
                                                                                          for a, b in pairs])), 1)}


def feet_check(rec, events: dict[str, FootEvents]) -> dict[str, Any] | None:
    """Both feet of a recording (``Recording``) whose foot sensors were worn; None when none was."""
    out = {}
    t = np.asarray(rec.raw.get("t", []), dtype=np.float64)
    if len(t) < 2 or len(rec.recon.get("t", [])) < 2:
        return None
    t0, t1 = float(rec.recon["t"][0]), float(rec.recon["t"][-1])
    for side in ("l", "r"):
        d = rec.raw.get(f"{side}_foot")
        if not d or "gyro" not in d or not np.isfinite(np.asarray(d["gyro"], dtype=np.float64)).any():
            continue
        out[side] = check(events[side], still_periods(t, d["gyro"], d["acc"], d.get("present")), t0, t1)
    return out or None
