"""Calibration of one trial from the other trials of its session: the walk that has no still start.

Why: people record a session as trials (an N-pose, a leg cycle per leg, several walks), and
a walk trial often starts with the subject already walking. Its sensors are the same,
strapped the same way, so their sensor-to-bone rotation R_SB is the N-pose trial's. What
is not shared is each sensor's heading reference: a Movella DOT (or an MTw without a
magnetic field it trusts) starts every trial with a heading of its own, so the N-pose's
R_GS and the walk's R_GS of one sensor differ by an unknown turn about the vertical.
Hence, per sensor k:

- **tilt** from the calibration trial's still stand (anywhere in it: ``standing.still_stand``);
- **its heading in the walk** (the subject's forward in the walk's frame G_w): the swing
  axis of thighs, shanks and feet over the straight walking, and for every sensor its
  path integrated back from a stop (a still moment of 0.3 s: velocity zero there; the
  walk need not start still), each turned back by the pelvis's turn since the walk's first
  second (``heading``, ``gait_heading``);
- **its heading in the calibration trial** (the subject's forward in that trial's G_c),
  which fixes the last degree of freedom of R_SB (the turn about the bone's long axis,
  which a still pose cannot see): the bone faces, on average over the straight walking,
  the way the subject walks (``facing``); for a thigh or shank whose leg was swung in a
  leg-cycle trial, its functional flexion axis instead (``flexion_axes``: the principal
  axis of its angular velocity in its own frame, lateral), as OpenSense's IMU placer and
  Xsens's functional calibrations use it.

Then R_WG (walk) = Rz(-heading_w) and R_SB = (Rz(-heading_c) R_GS,stand)^T R_WB,N-pose.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.body import npose_rotations
from inference.body.conventions import heading_of, mean_angle, rot_z, wrap_angle, yaw_of
from inference.body.rotations import quat_to_matrix
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX, parse_sites

from .core import Calibration, CalibrationError, StillnessLimits, _free_acc_G, calibrate_tpose
from .gait_heading import (
    MAX_BOUT_S,
    MIN_WALK_M,
    MOVING_M_S,
    UNSURE_DEG,
    _bouts,
    _not_turning,
    fill_gaps,
    pick_direction,
    still_frames,
    swing_forward,
    walk_displacements,
)
from .heading import heading_change, principal_axis, right_to_forward, still_mean, turn_back
from .standing import still_stand

LEG_SWING = ("l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")  # a clear lateral swing axis in gait
FLEXION = ("l_thigh", "r_thigh", "l_shank", "r_shank")  # a hinge in a leg cycle
FLEX_MIN_DEG_S = 60.0  # a leg segment turning faster than this in a calibration trial is swinging
FLEX_MIN_PLANAR = 0.85  # share of the swing's angular velocity energy about its one axis
FLEX_MIN_FRAMES = 30


@dataclass
class Trial:
    """One trial's sensors on the 60 Hz grid, in the order of the walk's sites (NaN and
    ``present`` False for a sensor the trial lacks). quat R_GS, rate rad/s in the sensor
    frame, acc the specific force."""

    name: str
    quat: np.ndarray  # (T,S,4)
    rate: np.ndarray  # (T,S,3)
    present: np.ndarray  # (T,S)
    fps: float
    acc: np.ndarray | None = None  # (T,S,3)


@dataclass
class TrialCalibration:
    """The walk's calibration, and per site where each part came from (``sensors``: site ->
    {stand, flexion_axis, heading, mounting})."""

    calibration: Calibration
    sensors: dict[str, dict] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def _ok(trial: Trial) -> np.ndarray:
    return np.all(np.isfinite(trial.quat), axis=-1) & np.asarray(trial.present, bool)


def _matrices(trial: Trial, ok: np.ndarray) -> np.ndarray:
    return quat_to_matrix(np.where(ok[..., None], trial.quat, [1.0, 0, 0, 0]))


def stands(sites: Sequence[str], trials: Sequence[Trial]) -> list[tuple[int, slice]]:
    """Per site, (calibration trial index, its still stand): the first trial, in the order
    given, that holds the sensor and a still stand. Raises the first refusal of a trial
    holding a sensor no trial could stand for."""
    found: list[tuple[int, slice] | None] = [None] * len(sites)
    errors: dict[int, CalibrationError] = {}
    for i, trial in enumerate(trials):
        ok = _ok(trial)
        held = ok.any(axis=0)
        if not held.any():
            continue
        try:
            still = still_stand(trial.rate, ok, trial.fps, name=trial.name)
        except CalibrationError as e:
            errors[i] = e
            continue
        for k in np.flatnonzero(held & ok[still].any(axis=0)):
            if found[k] is None:
                found[k] = (i, still)
    for k, f in enumerate(found):
        if f is None:
            bad = next((i for i, t in enumerate(trials) if i in errors and _ok(t)[:, k].any()), None)
            if bad is not None:
                raise errors[bad]
            raise CalibrationError(f"{sites[k]}: in no calibration trial's still stand "
                                   f"({', '.join(t.name for t in trials)})")
    return found  # type: ignore[return-value]


def flexion_axes(sites: Sequence[str], trials: Sequence[Trial]) -> tuple[np.ndarray, list[str | None]]:
    """Per site (S,3) the flexion axis in the sensor's own frame (sign arbitrary; NaN where
    no trial swung that segment) and the trial it came from: the principal axis of the
    angular velocity over the frames it turns faster than FLEX_MIN_DEG_S, from the trial
    where that swing is most planar (a leg-cycle trial, not a walk's twisting)."""
    S = len(sites)
    axes = np.full((S, 3), np.nan)
    source: list[str | None] = [None] * S
    best = np.zeros(S)
    for trial in trials:
        ok = _ok(trial) & np.all(np.isfinite(trial.rate), axis=-1)
        for k, s in enumerate(sites):
            if s not in FLEXION:
                continue
            w = trial.rate[ok[:, k], k]
            w = w[np.linalg.norm(w, axis=-1) > np.deg2rad(FLEX_MIN_DEG_S)]
            if len(w) < FLEX_MIN_FRAMES:
                continue
            ev = np.linalg.eigvalsh(w.T @ w)
            planar = float(ev[-1] / ev.sum())
            if planar >= FLEX_MIN_PLANAR and planar > best[k]:
                axes[k], source[k], best[k] = principal_axis(w), trial.name, planar
    return axes, source


def _open_displacement(a_G: np.ndarray, ok: np.ndarray, fps: float, stop: int, turn: np.ndarray | None,
                       bias: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S,2) path and (S,3,2) thirds of the moving frames' velocity over frames [0, stop):
    velocity integrated back from zero at the stop (the start's velocity is unknown), the
    stop's mean acceleration ``bias`` (S,3) removed."""
    S = a_G.shape[1]
    disp, thirds = np.full((S, 2), np.nan), np.full((S, 3, 2), np.nan)
    if stop / fps > MAX_BOUT_S:
        a_G, ok, turn = a_G[stop - int(MAX_BOUT_S * fps):stop], ok[stop - int(MAX_BOUT_S * fps):stop], (
            None if turn is None else turn[stop - int(MAX_BOUT_S * fps):stop])
    for k in range(S):
        good = ok[:, k] & np.all(np.isfinite(a_G[:, k]), -1)
        if good.mean() < 0.5 or not np.isfinite(bias[k]).all():
            continue
        a = fill_gaps(a_G[:, k] - bias[k], good, fps)
        v = np.cumsum(a, axis=0) / fps
        v = turn_back((v - v[-1])[:, :2], None if turn is None else np.nan_to_num(turn))
        disp[k] = v.sum(0) / fps
        moving = v[np.linalg.norm(v, axis=-1) > MOVING_M_S]
        if len(moving) >= 3:
            thirds[k] = [p.mean(0) for p in np.array_split(moving, 3)]
    return disp, thirds


def walk_forward(sites: Sequence[str], walk: Trial) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray]:
    """Per sensor the subject's forward (S,2) in its walk frame G_w (NaN where the walk does
    not say) and where it came from; the pelvis's turn since the walk's first second (T,)
    (None without a trunk sensor) and the straight walking frames (T,)."""
    sites = tuple(sites)
    ok = _ok(walk)
    R = _matrices(walk, ok)
    T, S = ok.shape
    fps = walk.fps
    anchor = next((sites.index(s) for s in ("pelvis", "torso") if s in sites and ok[:, sites.index(s)].any()), None)
    turn = None
    if anchor is not None:
        first = int(np.argmax(ok[:, anchor]))
        turn = heading_change(R[:, anchor], ok[:, anchor], still_mean(R[:, anchor], ok[:, anchor],
                                                                      slice(first, first + int(fps))))
    still = still_frames(walk.rate, ok, fps)
    straight = ~still & _not_turning(turn, fps)
    swing = np.full((S, 2), np.nan)
    swing_thirds = np.full((S, 3, 2), np.nan)
    for k, s in enumerate(sites):
        if s in LEG_SWING:
            f, th = swing_forward(walk.quat[:, k:k + 1], ok[:, k:k + 1], fps, (0, T), turn, straight, axis=True)
            swing[k], swing_thirds[k] = f[0], th[0]
    a_G = _free_acc_G(walk.quat, None, walk.acc) if walk.acc is not None else np.full((T, S, 3), np.nan)
    disp, parts = np.zeros((S, 2)), [[] for _ in range(S)]
    runs = _runs(still)
    for a, b in [(a, b) for a, b in _bouts(still, 0) if (b - a) / fps <= MAX_BOUT_S]:
        end = next((r for r in runs if r[0] <= b - 1 < r[1]), (b - 1, b))
        d, th = walk_displacements(a_G, ok, fps, (a, b), end, turn)
        disp += np.nan_to_num(d)
        for k in range(S):
            if np.isfinite(th[k]).all():
                parts[k].append(th[k])
    if runs and runs[0][0] > 0:  # moving from the first frame to the first stop
        a, b = runs[0]
        with np.errstate(invalid="ignore"):
            bias = np.nanmean(np.where(ok[a:b, :, None], a_G[a:b], np.nan), axis=0)
        d, th = _open_displacement(a_G[:a + 1], ok[:a + 1], fps, a + 1, None if turn is None else turn[:a + 1], bias)
        disp += np.nan_to_num(d)
        for k in range(S):
            if np.isfinite(th[k]).all():
                parts[k].append(th[k])
    if turn is None:
        disp[[k for k, s in enumerate(sites) if s not in LEG_SWING]] = np.nan
    disp_thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        if parts[k]:
            disp_thirds[k] = np.sum(parts[k], axis=0)
    disp[~(np.linalg.norm(disp, axis=-1) >= MIN_WALK_M)] = np.nan
    for k in range(S):  # where the sensor's path says which way it went, it signs the swing axis
        if np.isfinite(disp[k]).all() and np.isfinite(swing[k]).all() and float(disp[k] @ swing[k]) < 0:
            swing[k], swing_thirds[k] = -swing[k], -swing_thirds[k]
    direction, spread, source = pick_direction(sites, disp, disp_thirds, swing, swing_thirds, swing_sites=LEG_SWING)
    for k, s in enumerate(sites):  # a leg's swing axis needs no integration: where it is sure, it says
        if s in LEG_SWING and np.isfinite(swing[k]).all() and spread[k] <= UNSURE_DEG:
            direction[k], source[k] = swing[k], "swing axis"
    for k in range(S):
        if not np.isfinite(direction[k]).all():
            source[k] = "no swing, and no path back from a stop"
    return direction, source, turn, straight


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def facing(R_walk: np.ndarray, ok: np.ndarray, frames: np.ndarray, turn: np.ndarray | None, heading_w: float,
           R_stand: np.ndarray, R_rest: np.ndarray) -> float:
    """The heading (rad) of the subject's forward in the calibration trial's frame G_c that
    makes the bone face, on average over the straight walking, the way the subject walks:
    R_SB(h) = (Rz(-h) R_stand)^T R_rest, R_WB(t) = Rz(-heading_w) R_walk(t) R_SB(h). The
    bone's mean heading grows with h one for one while it stands upright, so a few fixed-point
    steps solve it for a swinging one too."""
    use = ok & frames & (np.isfinite(turn) if turn is not None else True)
    if use.sum() < 10:
        return float("nan")
    turned = np.nan_to_num(turn[use]) if turn is not None else 0.0
    h = 0.0
    for _ in range(4):
        R_SB = (rot_z(-h) @ R_stand).T @ R_rest
        psi = mean_angle(yaw_of(rot_z(-heading_w) @ R_walk[use] @ R_SB) - turned)
        h = float(wrap_angle(h - psi))
    return h


def calibrate_from_trials(sites: Sequence[str], walk: Trial, calibration: Sequence[Trial],
                          limits: StillnessLimits | None = None) -> TrialCalibration:
    """The walk's calibration from the calibration trials (module docstring); arrays of
    every trial in the walk's site order."""
    sites = tuple(parse_sites(list(sites)))
    if not calibration:
        raise ValueError("no calibration trial given")
    S = len(sites)
    where = stands(sites, calibration)
    axes, axis_from = flexion_axes(sites, calibration)
    forward, source, turn, straight = walk_forward(sites, walk)
    ok_w = _ok(walk)
    R_w = _matrices(walk, ok_w)
    rest = npose_rotations(1)[0]
    n = min(w[1].stop - w[1].start for w in where)
    quat_c = np.full((n, S, 4), np.nan)
    acc_c = np.full((n, S, 3), np.nan) if all(t.acc is not None for t in calibration) else None
    rate_c = np.full((n, S, 3), np.nan)
    R_stand = np.zeros((S, 3, 3))
    heading_w, heading_c = np.full(S, np.nan), np.full(S, np.nan)
    sensors: dict[str, dict] = {}
    warnings: list[str] = []
    for k, s in enumerate(sites):
        i, still = where[k]
        t = calibration[i]
        win = slice(still.start, still.start + n)
        quat_c[:, k], rate_c[:, k] = t.quat[win, k], t.rate[win, k]
        if acc_c is not None:
            acc_c[:, k] = t.acc[win, k]
        ok_c = _ok(t)[:, k]
        R_stand[k] = still_mean(_matrices(t, _ok(t))[:, k], ok_c, still)
        R_rest = rest[SITE_SEGMENT_INDEX[SITE_INDEX[s]]]
        info = {"stand": t.name, "flexion_axis": None, "heading": source[k], "mounting": None}
        if not np.isfinite(forward[k]).all():
            warnings.append(f"{s}: its heading in {walk.name} is unknown ({source[k]}); not calibrated")
            sensors[s] = info
            continue
        heading_w[k] = float(heading_of(forward[k]))
        h = facing(R_w[:, k], ok_w[:, k], straight, turn, heading_w[k], R_stand[k], R_rest)
        info["mounting"] = "walk facing"
        if np.isfinite(axes[k]).all():  # the flexion axis points right or left: the one nearer the facing's
            right = (R_stand[k] @ axes[k])[:2]
            h_axis = float(heading_of(right_to_forward(right)))
            if np.isfinite(h) and abs(wrap_angle(h_axis - h)) > np.pi / 2:
                h_axis = float(wrap_angle(h_axis + np.pi))
            h = h_axis
            info.update(mounting="flexion axis", flexion_axis=axis_from[k])
        heading_c[k] = h
        sensors[s] = info
    valid_h = np.isfinite(heading_w) & np.isfinite(heading_c)
    R_WG_c = rot_z(-np.nan_to_num(heading_c))
    present_c = np.all(np.isfinite(quat_c), axis=-1)
    R_SB, valid, resid = calibrate_tpose(sites, quat_c, R_WG_c, acc=acc_c, gyro=rate_c, present=present_c,
                                         R_WB_rest=rest, limits=limits)
    valid &= valid_h
    a_W = (R_WG_c[None] @ _free_acc_G(quat_c, None, acc_c)[..., None])[..., 0] if acc_c is not None else None
    offset = np.zeros((S, 3))
    if a_W is not None:
        with np.errstate(invalid="ignore"):
            offset = np.nan_to_num(np.nanmean(np.where(present_c[..., None], a_W, np.nan), axis=0))
    offset[~valid] = 0.0
    cal = Calibration(sites=sites, R_WG=rot_z(-np.nan_to_num(heading_w)), R_SB=R_SB, acc_offset=offset, valid=valid,
                      residual_tpose_deg=resid,
                      meta={"method": "calibration trial", "walk": walk.name, "forward_from": "gait (each sensor)",
                            "forward_G": [1.0, 0.0, 0.0], "still_frames": 0, "still_from": 0,
                            "sensors": sensors, "warnings": warnings})
    return TrialCalibration(cal, sensors, warnings)


__all__ = ["FLEXION", "LEG_SWING", "Trial", "TrialCalibration", "calibrate_from_trials", "facing", "flexion_axes",
           "stands", "walk_forward"]
