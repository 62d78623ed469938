"""How the reference and the reconstruction are put on one clock and one heading.

Time: the offset is the lag that maximises the correlation of the joint flexion angles
both sides have (knees, hips, elbows; ``kinematics.joint_angles``), averaged over the
joints: angles do not depend on heading, position or the systems' world frames, so the
clock is found before anything else is known. A coarse search over every lag at which
the two overlap by at least half the shorter (on the reconstruction's 20 Hz grid), then
a fine one (2 ms) around the best, then a parabola through the top three: the offset is
found well inside one reference frame. Its correlation is reported with it.

Heading: one rotation about the vertical for the whole trial, the least-squares one over
the segments both sides have: orientations when the reference has them
(sum of R_ref R_rec^T), else segment directions (sum of d_ref d_rec^T); the yaw of the
best Z rotation of a 3x3 sum M is ``conventions.yaw_of(M)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from inference.body.conventions import yaw_of

MIN_OVERLAP_FRACTION = 0.5
MIN_OVERLAP_S = 2.0
COARSE_STEP_S = 0.05
FINE_STEP_S = 0.002


@dataclass
class Alignment:
    """time_offset_s: reference clock minus recording clock (a reference frame at time s
    shows what the recording has at s - offset); correlation: the mean over ``joints`` of
    the angles' correlation at that offset; heading_deg: the yaw that turns the
    recording's world into the reference's."""

    time_offset_s: float
    correlation: float | None
    joints: list[str]
    heading_deg: float
    heading_from: str
    time_given: bool = False
    heading_given: bool = False


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


def find_time_offset(t_rec: np.ndarray, rec: dict[str, np.ndarray], t_ref: np.ndarray,
                     ref: dict[str, np.ndarray]) -> tuple[float, float, list[str]]:
    """(offset, correlation, joints used): module docstring."""
    joints = sorted(set(rec) & set(ref))
    if not joints:
        raise ValueError("the reference and the reconstruction share no joint angle (knee, hip, elbow) to find "
                         "the time offset from; give it with --time-offset")
    rec = {j: rec[j] for j in joints}
    ref = {j: np.where(np.isfinite(ref[j]), ref[j], np.interp(t_ref, t_ref[np.isfinite(ref[j])],
                                                                  ref[j][np.isfinite(ref[j])]))
           if np.isfinite(ref[j]).sum() >= 2 else ref[j] for j in joints}
    dur_rec, dur_ref = t_rec[-1] - t_rec[0], t_ref[-1] - t_ref[0]
    min_overlap = max(min(MIN_OVERLAP_S, 0.9 * min(dur_rec, dur_ref)), MIN_OVERLAP_FRACTION * min(dur_rec, dur_ref))
    lo, hi = t_ref[0] - t_rec[-1], t_ref[-1] - t_rec[0]
    lags = np.arange(lo, hi + COARSE_STEP_S, COARSE_STEP_S)
    scores = np.array([correlation_at(g, t_rec, rec, t_ref, ref, min_overlap) for g in lags])
    if not np.isfinite(scores).any():
        raise ValueError("the reference and the recording never overlap long enough to be compared "
                         f"(at least {min_overlap:.1f} s)")
    best = float(lags[int(np.argmax(scores))])
    fine = np.arange(best - 2 * COARSE_STEP_S, best + 2 * COARSE_STEP_S + 1e-9, FINE_STEP_S)
    fs = np.array([correlation_at(g, t_rec, rec, t_ref, ref, min_overlap) for g in fine])
    k = int(np.argmax(fs))
    lag = float(fine[k])
    if 0 < k < len(fine) - 1 and np.all(np.isfinite(fs[k - 1:k + 2])):
        a, b, c = fs[k - 1:k + 2]
        den = a - 2 * b + c
        if den < 0:
            lag += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) * FINE_STEP_S
    return lag, float(fs[k]), joints


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


__all__ = ["Alignment", "find_time_offset", "correlation_at", "heading_from_rotations", "heading_from_directions"]
