"""The few gait numbers a runner reads at a glance: cadence, knee flexion range per side,
and the left/right asymmetry of that range.

Why these: they are what a coach asks first and what a glance from a few metres can take
in; each comes from the reconstruction alone (segment orientations and foot contacts), so
it works with any sensor set that reconstructs the legs.

- Knee flexion: ``inference.metrics.joint_angles.knee_flexion_deg`` (ISB / OpenSim
  ``knee_angle``: the flexion component of the shank in the thigh, 0 standing straight),
  the same number validation, the exports and the gait report give.
- Range: 95th minus 5th percentile over the window, robust to a single bad frame.
- Cadence: foot strikes (a foot's contact, heel or toe, switching on: runners land on the
  forefoot) per minute over the window, both feet. A foot counts as coming down only after
  ``MIN_SWING_S`` in the air: contact flickering off and on around heel strike and toe off
  is not a step.
- Asymmetry: |left - right| / mean(left, right) of the knee range, in percent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.body.skeleton import CONTACTS
from inference.metrics import joint_angles

FEET = ((CONTACTS.index("l_heel"), CONTACTS.index("l_toe")), (CONTACTS.index("r_heel"), CONTACTS.index("r_toe")))
MIN_STRIKES = 3  # fewer strikes in the window: no cadence (standing, or not yet walking)
MIN_SWING_S = 0.15  # a swing phase lasts ~0.4 s walking, longer running; a flicker a few frames


@dataclass(frozen=True)
class GaitNumbers:
    cadence_spm: float | None
    knee_range_deg: tuple[float | None, float | None]  # left, right
    asymmetry_pct: float | None
    seconds: float  # the span of motion the numbers come from


def knee_flexion_deg(rot: np.ndarray) -> np.ndarray:
    """(T, 24, 3, 3) global segment orientations -> (T, 2) knee flexion, left and right (deg),
    as ``joint_angles.knee_flexion_deg``."""
    return np.stack([joint_angles.knee_flexion_deg(rot, s) for s in joint_angles.SIDES], axis=-1)


def debounced_contact(t: np.ndarray, down: np.ndarray, min_swing_s: float = MIN_SWING_S) -> np.ndarray:
    """(T,) bool: a foot's contact with every time in the air shorter than ``min_swing_s``
    filled in (a flicker off and on around heel strike or toe off is not a step); the time
    before the first contact counts as in the air since the window began. A time in the air
    still open at the window's end is kept."""
    t = np.asarray(t, dtype=np.float64)
    d = np.asarray(down, bool).copy()
    if not d.any():
        return d
    edges = np.flatnonzero(np.diff(d.astype(np.int8)))  # last index before each change
    starts = [0] + list(edges + 1)
    for a, b in zip(starts, [*starts[1:], len(d)]):
        if d[a] or b == len(d):  # a contact run, or the air run open at the end
            continue
        if t[b] - t[a] < min_swing_s:  # first frame up (or the window's start) to first frame down
            d[a:b] = True
    return d


def foot_strikes(t: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """Times at which either foot comes down (its heel or toe contact switching on after
    ``MIN_SWING_S`` in the air: ``debounced_contact``), sorted."""
    c = np.asarray(contacts, bool)
    t = np.asarray(t, dtype=np.float64)
    times = []
    for heel, toe in FEET:
        down = debounced_contact(t, c[:, heel] | c[:, toe]).astype(np.int8)
        times.extend(t[1:][np.diff(down) > 0])
    return np.sort(np.asarray(times, dtype=np.float64))


def gait_numbers(t: np.ndarray, rot: np.ndarray, contacts: np.ndarray) -> GaitNumbers:
    """The numbers over all of ``t`` (the caller keeps the window it wants)."""
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 2:
        return GaitNumbers(None, (None, None), None, 0.0)
    span = float(t[-1] - t[0])
    knee = knee_flexion_deg(rot)
    ranges = tuple(float(np.percentile(knee[:, k], 95) - np.percentile(knee[:, k], 5)) for k in range(2))
    strikes = foot_strikes(t, contacts)
    cadence = None
    if len(strikes) >= MIN_STRIKES and strikes[-1] > strikes[0]:
        cadence = 60.0 * (len(strikes) - 1) / float(strikes[-1] - strikes[0])
    mean = 0.5 * (ranges[0] + ranges[1])
    asym = 100.0 * abs(ranges[0] - ranges[1]) / mean if mean > 5.0 else None  # standing: no asymmetry to speak of
    return GaitNumbers(cadence, ranges, asym, span)
