"""How a replay compares with something else: the recorded live reconstruction at the same
session times (``compare_to_recorded``), a replay in which a left-out sensor was observed
(``held_out_errors``), a simulator's truth (``truth_errors``); and how two runs' frame
times are matched (``match_times``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.metrics.errors import global_angle_error
from inference.signals.resample import FPS_MODEL

if TYPE_CHECKING:
    from app.live import LivePose
    from app.recording import Recording


SAME_FRAME_S = 1e-6
"""A skipped frame's recorded time and the replay's time for it come from the same
resampler on the same recorded sample times: equal but for float formatting."""

MATCH_TOLERANCE_S = 0.5 / FPS_MODEL - 1e-6
"""Two runs' frames stand for the same moment when their times are under half a model
frame apart. Not exact equality: a live run that dropped 60 Hz frames under load (counted
in ``stats.dropped``) restarts its 20 Hz grid one or two 60 Hz samples off the replay's,
so its frame times sit 17 or 33 ms from the re-run's; the nearest frame is the same
moment to within the model's resolution."""


def match_times(a: np.ndarray, b: np.ndarray, tol: float = MATCH_TOLERANCE_S) -> np.ndarray:
    """For each time in ``a`` (sorted), the index of the nearest time in ``b`` (sorted) when
    it is within ``tol``, else -1."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(b) == 0:
        return np.full(len(a), -1)
    j = np.clip(np.searchsorted(b, a), 0, len(b) - 1)
    j_prev = np.clip(j - 1, 0, len(b) - 1)
    best = np.where(np.abs(b[j_prev] - a) < np.abs(b[j] - a), j_prev, j)
    return np.where(np.abs(b[best] - a) <= tol, best, -1)


def compare_to_recorded(rec: Recording, poses: Sequence[LivePose]) -> dict[str, Any]:
    """Mean global angle error (deg, the paper's GA over the body without hands/toes)
    between replayed poses and the recorded live ones at the same session times: how far
    a re-run (another model, fewer sensors) is from what was seen live. None when no
    frame times match (``match_times``)."""

    r = rec.recon
    if not poses or len(r["t"]) == 0:
        return {"vs_recorded_frames": 0, "vs_recorded_ga_deg": None}
    t_rep = np.array([lp.t for lp in poses])
    j = match_times(t_rep, r["t"])
    ok = j >= 0
    if not ok.any():
        return {"vs_recorded_frames": 0, "vs_recorded_ga_deg": None}
    R_rep = np.stack([lp.pose.rot for lp, o in zip(poses, ok) if o])
    ga = global_angle_error(R_rep, r["R"][j[ok]])
    return {"vs_recorded_frames": int(ok.sum()), "vs_recorded_ga_deg": round(float(np.mean(ga)), 3)}


def held_out_errors(poses: Sequence[LivePose], measured: Sequence[LivePose], sites: Sequence[str]) -> dict[str, Any]:
    """How far a reconstruction from fewer sensors is from what the left-out sensors
    measured: per site in ``sites``, the mean angle (deg) between its segment in ``poses``
    and in ``measured`` (a replay in which that site was observed, so its segment is the
    calibrated measurement), over the frames both replays produced at the same time and
    in which the site delivered. A real-data check that needs no motion capture, only a
    session recorded with more sensors than the set under test. ``axis_deg``: the same for
    the segment's long axis only (the turn about the bone left out)."""

    by_t = {round(lp.t, 6): lp for lp in measured}
    pairs = [(lp, by_t[round(lp.t, 6)]) for lp in poses if round(lp.t, 6) in by_t]
    out: dict[str, float | None] = {}
    axis: dict[str, float | None] = {}
    for s in sites:
        k, seg = SITE_INDEX[s], SITE_SEGMENT_INDEX[SITE_INDEX[s]]
        use = [(a, b) for a, b in pairs if b.observed_sites[k]]
        if not use:
            out[s] = axis[s] = None
            continue
        Ra = np.stack([a.pose.rot[seg] for a, _ in use])
        Rb = np.stack([b.pose.rot[seg] for _, b in use])
        out[s] = round(float(np.degrees(np.mean(matrix_angle_between(Ra, Rb)))), 2)
        d = _BONE_AXIS[seg]
        cos = np.einsum("tk,tk->t", Ra @ d, Rb @ d)
        axis[s] = round(float(np.degrees(np.mean(np.arccos(np.clip(cos, -1.0, 1.0))))), 2)
    vals = [v for v in out.values() if v is not None]
    avals = [v for v in axis.values() if v is not None]
    return {"frames": len(pairs), "deg": out, "mean_deg": round(float(np.mean(vals)), 2) if vals else None,
            "axis_deg": axis, "axis_mean_deg": round(float(np.mean(avals)), 2) if avals else None}


def _bone_axes() -> np.ndarray:
    """(24, 3) each segment's long axis in its own frame (rest pose: towards its main
    child; a leaf segment's is +X)."""
    from inference.body.body import MAIN_CHILD, anthropometric_offsets

    off = anthropometric_offsets(1.75)
    out = np.tile(np.array([1.0, 0.0, 0.0]), (len(off), 1))
    for seg, child in MAIN_CHILD.items():
        out[seg] = off[child] / np.linalg.norm(off[child])
    return out


# ``held_out_errors``' second figure: the angle between the two long axes leaves out the turn
# about the bone, the part a left-out sensor's own heading drift and twist put in its "truth"
# and the part the other sensors say least about (docs/real_signals.md)
_BONE_AXIS = _bone_axes()


def truth_errors(times: np.ndarray, R: np.ndarray, truth, max_lag: float = 0.2) -> dict[str, Any]:
    """GA (deg) of reconstructed global orientations ``R`` (T,24,3,3) at monotonic session
    ``times`` against a simulator's truth (``app.capture.simulate.Truth``), over the
    activity (the calibration protocol before it is not what a user records), and per
    segment. A frame's session time is when its samples arrived, which trails the moment
    the simulator played it by the transport's latency; the truth is compared at the lag
    (within ``max_lag`` s, reported as ``truth_lag_s``) that fits best, as a motion-capture
    system is synchronised to another before they are compared."""
    from inference.body.skeleton import SEGMENTS

    times = np.asarray(times, float)
    keep = times >= truth.t0 + truth.activity_start
    if not keep.any():
        return {"ga_deg": None, "truth_frames": 0, "truth_note": "no reconstructed frame in the activity"}
    tk = times[keep]
    inside = (tk - truth.t0) * truth.fps < len(truth.rot) - 0.5
    Rp, tk = np.asarray(R)[keep][inside], tk[inside]
    best = None
    for lag in np.arange(-max_lag, max_lag + 1e-9, 1.0 / truth.fps):
        ga = global_angle_error(Rp, truth.rot[truth.frame_at(tk - lag)])
        if best is None or ga.mean() < best[0]:
            best = (float(ga.mean()), float(lag), ga)
    Rt = truth.rot[truth.frame_at(tk - best[1])]
    seg = np.rad2deg(matrix_angle_between(Rp, Rt)).mean(axis=0)
    return {"ga_deg": best[0], "truth_lag_s": round(best[1], 4), "truth_frames": int(len(best[2])),
            "ga_segment_deg": {SEGMENTS[k]: round(float(seg[k]), 2) for k in range(len(SEGMENTS))}}
