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

Where both foot sensors were worn and calibrated they are also the event source (``sensor_events``, chosen
by ``app.report.analysis.analyse_recording`` over the model's contacts, after the insoles): the foot's
angular rate about its medio-lateral axis (the bone's y axis, left, through the calibration's
sensor-to-bone: plantarflexion positive) swings through one large negative peak per stride, mid-swing;
the positive peak before it is foot off (the foot rolling over its toes), and the first positive peak
after it is foot strike (the foot slapping flat once the heel is down). These are the events of Rampp et
al. 2014 (IEEE TBME 62(4), the method gaitmap ships as ``RamppEventDetection``, there without its
acceleration refinement of the strike); gaitmap itself is not used for the reasons in ``events``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.signal import find_peaks

from .events import SIDES, FootEvents, Stance, debounce

STILL_GYRO = 1.0  # rad/s (57 deg/s): a foot rolling over heel or toe turns faster, a flat foot hardly at all
STILL_ACC = 2.0  # m/s^2 about g
WINDOW_S = 0.1
MIN_STILL_S = 0.1
COVER = 0.5  # share of a still period a found stance must cover
SWING_RATE = np.radians(100.0)  # rad/s: a walking mid-swing peaks at 250-450 deg/s, a shuffle or a sway under 100
MIN_SWING_GAP_S = 0.5  # two mid-swing peaks of one foot at least this far apart (a stride lasts 0.8-2 s)
SEARCH_S = 0.45  # foot off is looked for this long before the mid-swing peak, foot strike this long after


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
    for i, j in true_runs(win):
        start, end = float(t[max(i - half, 0)]), float(t[min(j + half, len(t) - 1)])
        if end - start >= MIN_STILL_S:
            out.append((start, end))
    return out


def true_runs(mask: np.ndarray, starts: np.ndarray | None = None) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as (first, last) sample indices; ``starts``: samples that
    begin a new run even inside one (after a gap in time)."""
    mask = np.asarray(mask, dtype=bool)
    runs: list[tuple[int, int]] = []
    i = 0
    while i < len(mask):
        if not mask[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(mask) and mask[j + 1] and not (starts is not None and starts[j + 1]):
            j += 1
        runs.append((i, j))
        i = j + 1
    return runs


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
        gyro = foot_gyro(d, t) if d else None
        if gyro is None or "acc" not in d:
            continue
        out[side] = check(events[side], still_periods(t, gyro, d["acc"], d.get("present")), t0, t1)
    return out or None


def foot_gyro(d: dict, t: np.ndarray) -> np.ndarray | None:
    """(T, 3) a foot sensor's angular rate in its own frame (rad/s): its gyro where the recording holds
    one, else from its orientations (log(R(t-1)^T R(t+1)) / 2 dt, what a gyro reads less the sensor
    filter's lag; an OpenSense / MT Manager export of orientations only); None with neither."""
    gyro = np.asarray(d.get("gyro", np.zeros((0, 3))), dtype=np.float64)
    if len(gyro) == len(t) and np.isfinite(gyro).any():
        return gyro
    q = np.asarray(d.get("quat", np.zeros((0, 4))), dtype=np.float64)
    if len(q) != len(t) or len(t) < 3 or not np.isfinite(q).any():
        return None
    from inference.body.rotations import quat_to_matrix
    from inference.signals.synthesis import angular_velocity

    fin = np.all(np.isfinite(q), axis=1)
    R = quat_to_matrix(np.where(fin[:, None], q, [1.0, 0.0, 0.0, 0.0]))
    w = angular_velocity(R, 1.0 / float(np.median(np.diff(t))))
    bad = ~fin
    bad[1:] |= ~fin[:-1]
    bad[:-1] |= ~fin[1:]
    w[bad] = np.nan
    return w


def sagittal_rate(gyro: np.ndarray, R_SB: np.ndarray) -> np.ndarray:
    """(T,) the foot's angular rate about its bone's y axis (medio-lateral, pointing left; rad/s,
    plantarflexion positive) from the sensor's gyro (T, 3) and the calibration's R_SB (bone -> sensor):
    omega_B = R_SB^T omega_S."""
    return np.asarray(gyro, dtype=np.float64) @ np.asarray(R_SB, dtype=np.float64)[:, 1]


def _peak_time(t: np.ndarray, w: np.ndarray, i: int) -> float:
    """The time of the peak at sample i refined by a parabola through it and its neighbours."""
    if 0 < i < len(w) - 1:
        a, b, c = w[i - 1], w[i], w[i + 1]
        den = a - 2 * b + c
        if den != 0:
            d = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
            return float(t[i] + d * (t[i + 1] - t[i]) if d >= 0 else t[i] + d * (t[i] - t[i - 1]))
    return float(t[i])


def _run_stances(t: np.ndarray, w: np.ndarray, swing_rate: float) -> list[Stance]:
    """One stretch of valid samples: the stances between its mid-swing peaks (module docstring); the
    stretch's ends cut the first and last stance without an event there."""
    if len(t) < 3:
        return []
    fs = 1.0 / float(np.median(np.diff(t)))
    peaks, _ = find_peaks(-w, height=swing_rate, prominence=swing_rate,
                          distance=max(1, int(MIN_SWING_GAP_S * fs)))
    n = max(1, int(round(SEARCH_S * fs)))
    out: list[Stance] = []
    start, strike_seen = float(t[0]), False  # the stance before the first swing began before the data
    for p in peaks:
        a = max(0, p - n)
        off_i = a + int(np.argmax(w[a: p + 1]))
        if w[off_i] > 0 and off_i > 0:  # a real roll over the toes, inside the data
            out.append(Stance(start, _peak_time(t, w, off_i), strike_seen, True))
        # foot strike: the first positive local maximum after the rate comes back through zero
        b = min(len(w) - 1, p + n)
        pos = np.nonzero(w[p: b + 1] > 0)[0]
        strike_i = None
        if len(pos):
            k = p + int(pos[0])
            while k < b and w[k + 1] >= w[k]:
                k += 1
            if k < len(w) - 1:
                strike_i = k
        start, strike_seen = (_peak_time(t, w, strike_i), True) if strike_i is not None else (float(t[p]), False)
    if peaks.size:
        out.append(Stance(start, float(t[-1]), strike_seen, False))
    else:
        out.append(Stance(float(t[0]), float(t[-1]), False, False))  # no swing: one stance cut at both ends
    return [s for s in out if s.end > s.start]


def split_pivots(stances: list[Stance], periods: list[tuple[float, float]], t: np.ndarray, rate: np.ndarray,
                 swing_rate: float = SWING_RATE) -> list[Stance]:
    """A stance that holds two still periods of the foot with a move between them faster than
    ``swing_rate`` (|angular rate|, any axis) is two stances: a step turning on the spot swings the foot
    about its vertical axis, which the sagittal peaks do not see. The split's events are the still
    periods' ends (foot off when the foot starts moving, strike when it is still again): later and
    earlier than the real ones, and such strides turn, so the report leaves them out."""
    out: list[Stance] = []
    for s in stances:
        inside = [(a, b) for a, b in periods if a >= s.start - 1e-9 and b <= s.end + 1e-9]
        cur = s
        for (_, b1), (a2, _) in zip(inside[:-1], inside[1:]):
            between = (t > b1) & (t < a2)
            if between.any() and np.nanmax(rate[between]) > swing_rate:
                out.append(Stance(cur.start, b1, cur.strike, True))
                cur = Stance(a2, cur.end, True, cur.off)
        out.append(cur)
    return out


def sensor_events(t: np.ndarray, gyro: np.ndarray, R_SB: np.ndarray, present: np.ndarray | None = None,
                  side: str = "l", swing_rate: float = SWING_RATE, acc: np.ndarray | None = None) -> FootEvents:
    """One foot's events from its sensor's gyro (T, 3, rad/s, sensor frame) at times ``t`` and its
    sensor-to-bone R_SB; samples not ``present`` or not finite cut the data like a gap (no event made
    up there). With its specific force ``acc`` (T, 3) the still periods also split stances that hold a
    step turning on the spot (``split_pivots``)."""
    t = np.asarray(t, dtype=np.float64)
    w = sagittal_rate(gyro, R_SB)
    ok = np.isfinite(w) & (np.ones(len(t), bool) if present is None else np.asarray(present, dtype=bool))
    gap = 2.5 * float(np.median(np.diff(t))) if len(t) > 1 else np.inf
    new_run = np.ones(len(t), dtype=bool)  # sample i starts a new stretch (after a gap in time)
    new_run[1:] = np.diff(t) > gap
    stances: list[Stance] = []
    for i, j in true_runs(ok, new_run):
        stances += _run_stances(t[i: j + 1], w[i: j + 1], swing_rate)
    if acc is not None:
        rate = np.linalg.norm(np.asarray(gyro, dtype=np.float64), axis=1)
        stances = split_pivots(stances, still_periods(t, gyro, acc, ok), t, rate, swing_rate)
    return FootEvents(side, debounce(stances), "foot sensors")


def foot_sensor_events(rec) -> dict[str, FootEvents] | None:
    """Both feet's events from a recording's (``Recording``) foot sensors, when both were worn, sent
    their gyro (or orientations: ``foot_gyro``) for most of the recording and were calibrated (their
    sensor-to-bone gives the foot's medio-lateral axis); None otherwise."""
    t = np.asarray(rec.raw.get("t", []), dtype=np.float64)
    if len(t) < 3 or not rec.calibrations:
        return None
    cal = rec.calibrations[-1][1]
    out = {}
    for side in SIDES:
        site = f"{side}_foot"
        d = rec.raw.get(site)
        gyro = foot_gyro(d, t) if d else None
        if gyro is None or site not in cal.sites or not cal.valid[cal.sites.index(site)]:
            return None
        present = np.asarray(d.get("present", np.ones(len(t), bool)), dtype=bool) & np.all(np.isfinite(gyro), axis=1)
        if present.mean() < 0.5:
            return None
        acc = d.get("acc")
        acc = None if acc is None or not np.isfinite(np.asarray(acc, dtype=np.float64)).any() else acc
        out[side] = sensor_events(t, gyro, cal.R_SB[cal.sites.index(site)], present, side, acc=acc)
    return out
