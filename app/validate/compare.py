"""The numbers a validation paper reports, for one reconstruction against the reference
once both are on one clock and heading (``align.py``).

Per segment: the mean and RMS over frames of the angle between the two orientations
(geodesic, deg) where the reference has the segment's orientation, else between the two
segment directions (``kinematics.DIRECTIONS``: markers do not show a bone's twist);
``segment_error`` says which. The hands, fingers and toes are left out, as in every
metric here (``inference.metrics.errors.EVAL_SEGMENTS``). Per joint (``l_knee``, ...;
the angles of ``inference.metrics.joint_angles``, paired as ``kinematics`` says):
the RMS of the angle difference, the range (max - min) of each side over the
trial, and per window of ``WINDOW_S`` the two ranges, for Bland-Altman.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.validate.kinematics import directions, paired_joint_angles
from app.validate.reference import Reference
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import METRIC_EXCLUDED, SEGMENT_INDEX, SEGMENTS

WINDOW_S = 2.0


@dataclass
class Track:
    """One side's motion on the recording's clock: times (T,) s since the recording's first
    raw frame, orientations (T, 24, 3, 3) or None, joint centres (T, 24, 3), the joint
    names it has; frames: segment frames from markers (``Reference.frames``) or None."""

    t: np.ndarray
    rot: np.ndarray | None
    joints: np.ndarray
    have_joints: set[str]
    have_rot: set[str] = field(default_factory=lambda: set(SEGMENTS))
    frames: np.ndarray | None = None
    have_frames: set[str] = field(default_factory=set)


def reference_at(ref: Reference, t: np.ndarray) -> tuple[np.ndarray, Track]:
    """(mask of ``t`` inside the reference, the reference at those times): joint centres
    interpolated linearly, orientations at the nearest frame."""
    inside = (t >= ref.t[0]) & (t <= ref.t[-1])
    tq = t[inside]
    J = np.empty((len(tq), ref.joints.shape[1], 3))
    for j in range(ref.joints.shape[1]):
        for c in range(3):
            J[:, j, c] = np.interp(tq, ref.t, ref.joints[:, j, c])
    k = np.clip(np.searchsorted(ref.t, tq), 1, len(ref.t) - 1)
    k -= (tq - ref.t[k - 1]) < (ref.t[k] - tq)
    rot = None if ref.rot is None else ref.rot[k]
    frames = None if ref.frames is None else ref.frames[k]
    return inside, Track(tq, rot, J, ref.have_joints, ref.have_rot, frames, ref.have_frames)


def range_deg(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(x.max() - x.min()) if len(x) else float("nan")


def compare(rec: Track, ref: Track, fps: float) -> dict[str, Any]:
    """Per-segment and per-joint errors of ``rec`` against ``ref`` (the same frames, the
    same world); module docstring. The JSON-able dict of one subset."""
    out_seg: dict[str, float] = {}
    out_rms: dict[str, float] = {}
    kind: dict[str, str] = {}
    d_rec, d_ref = directions(rec.joints, rec.have_joints), directions(ref.joints, ref.have_joints)
    for s in SEGMENTS:
        if s in METRIC_EXCLUDED:
            continue
        i = SEGMENT_INDEX[s]
        if ref.rot is not None and rec.rot is not None and s in ref.have_rot and s in rec.have_rot:
            e = np.rad2deg(matrix_angle_between(rec.rot[:, i], ref.rot[:, i]))
            kind[s] = "orientation"
        elif s in d_rec and s in d_ref:
            e = np.rad2deg(np.arccos(np.clip(np.sum(d_rec[s] * d_ref[s], axis=-1), -1.0, 1.0)))
            kind[s] = "direction"
        else:
            continue
        e = e[np.isfinite(e)]
        if len(e):
            out_seg[s], out_rms[s] = round(float(e.mean()), 3), round(float(np.sqrt(np.mean(e * e))), 3)
    a_rec, a_ref = paired_joint_angles(rec, ref)
    joints: dict[str, dict[str, Any]] = {}
    n_win = max(int(round(WINDOW_S * fps)), 2)
    for j in sorted(set(a_rec) & set(a_ref)):
        x, y = a_rec[j], a_ref[j]
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 2:
            continue
        d = x[ok] - y[ok]
        wins = [(range_deg(x[k:k + n_win]), range_deg(y[k:k + n_win])) for k in range(0, len(x) - n_win + 1, n_win)]
        joints[j] = {"rms_deg": round(float(np.sqrt(np.mean(d * d))), 3), "bias_deg": round(float(d.mean()), 3),
                     "range_deg": round(range_deg(x), 3), "reference_range_deg": round(range_deg(y), 3),
                     "window_ranges_deg": [[round(a, 2), round(b, 2)] for a, b in wins
                                           if np.isfinite(a) and np.isfinite(b)]}
    values = list(out_seg.values())
    return {"segments": out_seg, "segments_rms": out_rms, "segment_error": kind,
            "mean_deg": round(float(np.mean(values)), 3) if values else None, "joints": joints,
            "frames": int(len(rec.t))}


def bland_altman(pairs: list[list[float]]) -> dict[str, float] | None:
    """Bias and 95% limits of agreement (imucap - reference) of paired ranges."""
    if len(pairs) < 2:
        return None
    a = np.asarray(pairs, float)
    d = a[:, 0] - a[:, 1]
    bias, sd = float(d.mean()), float(d.std(ddof=1))
    return {"bias_deg": round(bias, 3), "loa_low_deg": round(bias - 1.96 * sd, 3),
            "loa_high_deg": round(bias + 1.96 * sd, 3), "n": int(len(d))}


__all__ = ["Track", "reference_at", "compare", "bland_altman", "range_deg", "WINDOW_S"]
