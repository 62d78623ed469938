"""Gait events (foot strike, foot off) from foot contact signals, debounced.

A foot is in stance while its heel or its toe touches the ground (``inference.body.skeleton.CONTACTS``
order: l_heel, l_toe, r_heel, r_toe): stance runs from the first point down (foot strike, the heel in a
normal walk) to the last one up (foot off, the toe). The signal is whatever the recording holds, best
first (``contact_source``):

- ``insoles``: the insoles' own heel/toe contacts (60 Hz), when they were worn;
- ``model``: the poser's contact values (20 Hz, ``recon/contact_prob`` in [0, 1], a contact above
  ``inference.poser.models.CONTACT_THRESHOLD``); with both shanks worn these come from the shank contact
  detector (``inference/poser/contact_detector.py``), otherwise from the model's own contact features.
  The poser's first ``WARMUP_S`` are not read (``model_contact_values``): its detector reads the last
  0.45 s of the shanks and its model the last 3 s, and at the start of a reconstruction that is the
  standing history the poser starts from, not the subject (strides that began there were off by 35 ms
  on the synthesized walks, against 16 later; docs/report.md).
- for a motion with its truth (synthesized walks): the heel/toe points' speed below
  ``inference.signals.synthesis.CONTACT_SPEED`` (``truth_contact_values``).

Where a continuous value crosses the threshold between two frames, the event time is interpolated
linearly between them: at 20 Hz that halves the quantisation (50 ms frames) of the timing.

Debouncing (``debounce``), in this order: a gap in contact shorter than ``MIN_SWING_S`` is closed (the
heel lifting a frame before the toe lands, a contact flickering at heel strike); a contact shorter than
``MIN_STANCE_S`` is dropped (a foot brushing the ground in swing). A stance that touches either end of
the data, or a stretch where the signal is missing, has no event at that end: it is cut, not seen to
begin or end.

Why not a library: gaitmap (the maintained one for foot-worn IMUs) needs numpy < 2.1, pandas and numba,
and detects events from a foot sensor's raw gyroscope, which most sensor sets here do not have; the
model's contacts are a per-frame signal that needs only the threshold and the debouncing above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.body.skeleton import CONTACTS
from inference.poser.contact_detector import CONTEXT as DETECTOR_CONTEXT
from inference.poser.models import CONTACT_THRESHOLD
from inference.signals.resample import FPS_MODEL

SIDES = ("l", "r")
FOOT_POINTS = {"l": (CONTACTS.index("l_heel"), CONTACTS.index("l_toe")),
               "r": (CONTACTS.index("r_heel"), CONTACTS.index("r_toe"))}
MIN_SWING_S = 0.15  # a walking swing lasts ~0.4 s: a shorter gap in contact is a flicker, not a swing
MIN_STANCE_S = 0.12  # a walking stance lasts ~0.6 s (running ~0.25): a shorter contact is a brush in swing
GAP_FACTOR = 2.5  # consecutive samples further apart than this many median periods: the data has a gap
WARMUP_S = DETECTOR_CONTEXT / FPS_MODEL  # the poser's start, whose contacts read its made-up standing history


@dataclass(frozen=True)
class Stance:
    """One contact of a foot: [start, end] in s; ``strike`` / ``off``: whether that end is a real event
    (False where the stance touches the data's start or end, or a gap)."""

    start: float
    end: float
    strike: bool = True
    off: bool = True


@dataclass
class FootEvents:
    """The stances of one foot, in time order; ``source`` says which signal gave them."""

    side: str
    stances: list[Stance]
    source: str

    @property
    def strikes(self) -> np.ndarray:
        return np.array([s.start for s in self.stances if s.strike], dtype=np.float64)

    @property
    def offs(self) -> np.ndarray:
        return np.array([s.end for s in self.stances if s.off], dtype=np.float64)


def _runs(t: np.ndarray, value: np.ndarray, threshold: float, gap_s: float) -> list[Stance]:
    """Stretches where ``value > threshold``, their ends interpolated between frames; NaN values and gaps
    in ``t`` longer than ``gap_s`` cut a run without an event at the cut."""
    out: list[Stance] = []
    n = len(t)
    if n == 0:
        return out
    finite = np.isfinite(value)
    on = finite & (value > threshold)
    cut_after = np.zeros(n, dtype=bool)  # data missing between sample i and i + 1
    cut_after[:-1] = (np.diff(t) > gap_s) | ~finite[:-1] | ~finite[1:]
    cut_after[-1] = True

    def crossing(i: int) -> float:
        """Time at which the value crosses the threshold between sample i and i + 1."""
        a, b = float(value[i]), float(value[i + 1])
        if b == a:
            return float(0.5 * (t[i] + t[i + 1]))
        w = min(max((threshold - a) / (b - a), 0.0), 1.0)
        return float(t[i] + w * (t[i + 1] - t[i]))

    i = 0
    while i < n:
        if not on[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and on[j + 1] and not cut_after[j]:
            j += 1
        seen_start = i > 0 and not cut_after[i - 1]
        seen_end = j < n - 1 and not cut_after[j]
        start = crossing(i - 1) if seen_start else float(t[i])
        end = crossing(j) if seen_end else float(t[j])
        out.append(Stance(start, end, seen_start, seen_end))
        i = j + 1
    return out


def debounce(stances: list[Stance], min_swing_s: float = MIN_SWING_S,
             min_stance_s: float = MIN_STANCE_S) -> list[Stance]:
    """Close gaps shorter than ``min_swing_s`` between seen ends, then drop stances shorter than
    ``min_stance_s`` whose both ends were seen (a cut stance may be longer than what is left of it)."""
    merged: list[Stance] = []
    for s in stances:
        if merged and merged[-1].off and s.strike and s.start - merged[-1].end < min_swing_s:
            last = merged.pop()
            s = Stance(last.start, s.end, last.strike, s.off)
        merged.append(s)
    return [s for s in merged if not (s.strike and s.off and s.end - s.start < min_stance_s)]


def foot_events(t: np.ndarray, values: np.ndarray, source: str, threshold: float = CONTACT_THRESHOLD,
                min_swing_s: float = MIN_SWING_S, min_stance_s: float = MIN_STANCE_S) -> dict[str, FootEvents]:
    """Both feet's events from (T, 4) contact values (bool or in [0, 1]) at times ``t`` (s, increasing)."""
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != len(CONTACTS) or len(t) != len(v):
        raise ValueError(f"contacts must be (T, {len(CONTACTS)}) beside T times, not {v.shape} and {t.shape}")
    gap = GAP_FACTOR * float(np.median(np.diff(t))) if len(t) > 1 else np.inf
    out = {}
    for side in SIDES:
        heel, toe = FOOT_POINTS[side]
        foot = np.fmax(v[:, heel], v[:, toe])  # either point down: the foot is down
        foot[~(np.isfinite(v[:, heel]) | np.isfinite(v[:, toe]))] = np.nan
        stances = debounce(_runs(t, foot, threshold, gap), min_swing_s, min_stance_s)
        out[side] = FootEvents(side, stances, source)
    return out


def model_contact_values(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The poser's contact values (T, 4) at times ``t`` with its warm-up, the first ``WARMUP_S`` of the
    reconstruction, missing (NaN): a stance running into it has no strike (module docstring)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.array(values, dtype=np.float64, copy=True)
    if len(t):
        out[t < t[0] + WARMUP_S - 1e-9] = np.nan
    return out


def truth_contact_values(contact_points: np.ndarray, fps: float) -> np.ndarray:
    """(T, 4) contact values of a motion's heel/toe points (T, 4, 3): 1 - speed / CONTACT_SPEED, so that
    the threshold 0 sits at the labels' speed and the crossing is interpolated like the model's values.
    ``foot_events(t, values, "truth", threshold=0.0)`` gives the truth's events."""
    from inference.signals.synthesis import CONTACT_SPEED

    p = np.asarray(contact_points, dtype=np.float64)
    if len(p) < 2:
        return np.ones(p.shape[:2])
    speed = np.linalg.norm(np.gradient(p, 1.0 / fps, axis=0), axis=-1)
    return 1.0 - speed / CONTACT_SPEED


def contact_source(recon: dict, raw: dict | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """(t, values, source) of a recording's best contact signal: the insoles' contacts where they were
    worn (and present for most of the reconstruction), else the poser's contact values."""
    if raw is not None and "insoles" in raw:
        ins = raw["insoles"]
        present = np.asarray(ins.get("present", []), dtype=bool)
        if len(present) and present.mean() > 0.5 and "contacts" in ins:
            vals = np.asarray(ins["contacts"], dtype=np.float64).copy()
            vals[~present] = np.nan
            return np.asarray(raw["t"], dtype=np.float64), vals, "insoles"
    prob = recon.get("contact_prob")
    if prob is None or not np.isfinite(np.asarray(prob, dtype=np.float64)).any():
        prob = recon["contacts"]
    t = np.asarray(recon["t"], dtype=np.float64)
    return t, model_contact_values(t, prob), "model"


ZENI_MIN_STEP_S = 0.6  # same-foot extremes closer than this are one (a walking stride is ~1.0-1.3 s)
ZENI_DIRECTION_S = 1.0  # the walking direction: the pelvis' horizontal path over about a stride


def coordinate_events(t: np.ndarray, contact_points: np.ndarray, pelvis: np.ndarray,
                      source: str = "coordinates") -> dict[str, FootEvents]:
    """Both feet's events from marker-like positions by the coordinate method of Zeni, Richards and
    Higginson (Gait & Posture 2008): along the walking direction, a foot strikes when its heel is
    furthest ahead of the pelvis and comes off when its toe is furthest behind it.

    Why beside the heel/toe speed rule: a speed threshold depends on the skeleton's feet (a rigid foot's
    toe rises with the heel, ending the stance early) and gives stances of 44-49 % on some motion-capture
    walks, which no walk has; the coordinate method is the standard for walks captured without force
    plates (strike within ~16 ms of a force plate's, foot off ~10 ms in that paper) and reads only where
    the foot is, not how fast it moves. Straight walking only: in a turn or a stand the extremes are not
    events (the report leaves such strides out anyway).

    t: (T,) s; contact_points: (T, 4, 3) heel/toe points (``CONTACTS`` order), pelvis: (T, 3), metres, Z
    up. Each extreme is refined by a parabola through its three samples. A stance runs from a strike to
    the next foot off; one cut by the data's start or end has no event there."""
    from scipy.ndimage import uniform_filter1d
    from scipy.signal import find_peaks

    t = np.asarray(t, dtype=np.float64)
    p = np.asarray(contact_points, dtype=np.float64)
    pel = np.asarray(pelvis, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(CONTACTS), 3) or pel.shape != (len(p), 3) or len(t) != len(p):
        raise ValueError(f"need (T, {len(CONTACTS)}, 3) points, a (T, 3) pelvis and T times: "
                         f"{p.shape}, {pel.shape}, {t.shape}")
    out = {side: FootEvents(side, [], source) for side in SIDES}
    if len(t) < 5:
        return out
    dt = float(np.median(np.diff(t)))
    vel = np.gradient(pel[:, :2], t, axis=0)
    vel = uniform_filter1d(vel, size=max(1, int(round(ZENI_DIRECTION_S / dt))), axis=0, mode="nearest")
    speed = np.linalg.norm(vel, axis=1, keepdims=True)
    direction = np.divide(vel, speed, out=np.zeros_like(vel), where=speed > 1e-6)
    distance = max(1, int(round(ZENI_MIN_STEP_S / dt)))

    def extremes(x: np.ndarray) -> np.ndarray:
        idx, _ = find_peaks(x, distance=distance)  # never the first or last sample
        a, b, c = x[idx - 1], x[idx], x[idx + 1]
        den = a - 2.0 * b + c
        shift = np.divide(0.5 * (a - c), den, out=np.zeros_like(b), where=np.abs(den) > 1e-12)
        return np.interp(idx + np.clip(shift, -0.5, 0.5), np.arange(len(t)), t)

    ahead = np.einsum("tkj,tj->tk", p[:, :, :2] - pel[:, None, :2], direction)  # (T, 4) along the walk
    for side in SIDES:
        heel, toe = FOOT_POINTS[side]
        events = sorted([(s, "strike") for s in extremes(ahead[:, heel])]
                        + [(o, "off") for o in extremes(-ahead[:, toe])])
        stances: list[Stance] = []
        start: float | None = None
        for i, (time, kind) in enumerate(events):
            if kind == "strike":
                start = time
            elif start is not None:
                stances.append(Stance(start, time))
                start = None
            elif i == 0:  # the data starts in this stance
                stances.append(Stance(float(t[0]), time, strike=False))
        if start is not None:
            stances.append(Stance(start, float(t[-1]), off=False))
        out[side] = FootEvents(side, stances, source)
    return out
