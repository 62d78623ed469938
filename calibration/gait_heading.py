"""Each sensor's heading from gait: where "forward" is in that sensor's own reference frame.

Why: a still pose fixes a sensor's tilt, never its heading (a turn of its reference frame
about the vertical cannot be told from a turn of its strap). Walking tells it, twice:

- **Displacement.** Every point of the body travels the same metres forward. A sensor's
  free acceleration, bias removed, integrated between two still moments (velocity zero at
  both, so a constant bias's linear drift is removed with the line through the end
  value) gives its path in its own frame G.
- **Swing axis.** Thighs and shanks swing about the body's left-right axis, fastest when
  their lower end goes forward: the horizontal part of the fastest tenth of their
  angular velocity points to the subject's right. It needs no acceleration, so it holds
  where an AHRS leaks gravity into the free acceleration during fast swings.

Both are taken per sensor in its own frame, so sensors whose frames do not share a
heading (6-axis sensors, a magnetometer disturbed at one foot) each get their own. The
live ``walk`` protocol (``calibration.walk``: one straight walk) and ``imucap import``
(``gait_headings``: any walking in a log, with turns) use these same functions. In a log
the subject turns: each frame's vector is turned back by how far the subject has turned
since the stand (the pelvis's heading change, which does not depend on the pelvis
sensor's own heading offset), so a walk back after a turn votes for the same forward.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.rotations import quat_to_matrix, so3_log

from .core import _free_acc_G
from .heading import axis_forward, heading_change, peak_forward, still_mean, turn_back

SWING_SEGMENTS = ("l_thigh", "r_thigh", "l_shank", "r_shank")
MIN_WALK_M = 1.0  # shorter than this and a bias of 0.05 m/s^2 is a few degrees of heading
MIN_PRESENT = 0.5  # of the walk's frames, per sensor
LONG_GAP_S = 0.25  # missing longer than this, a stream's velocity is held across the gap (``fill_gaps``)
MOVING_M_S = 0.3  # the still ends of a walk say nothing of its direction
MIN_SWING_FRAMES = 30
WARN_DEG = 15.0  # a heading this far from the others' is named in the report
UNSURE_DEG = 20.0  # an estimate whose thirds disagree by more is not used
STILL_DEG_S = 15.0  # every sensor slower than this: standing
MIN_STILL_S = 0.3
MAX_BOUT_S = 10.0  # integrated longer, a real accelerometer's drift is no longer a line
STEP_DEG_S = 90.0  # a leg segment's swing peaks exceed this in any walk
TURN_DEG_S = 30.0  # the subject turning faster than this is not walking straight
MIN_STEPS = 4  # swing peaks of one leg segment that make a log "hold walking"


def angle_between_2d(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unsigned angle (deg) between 2-D vectors, broadcast over leading axes."""
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    return np.abs(np.rad2deg(np.arctan2(cross, np.sum(u * v, -1))))


def signed_angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle (deg) that turns 2-D u onto v, counter-clockwise positive, in (-180, 180]."""
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    return np.rad2deg(np.arctan2(cross, np.sum(u * v, -1)))


def fill_gaps(a: np.ndarray, ok: np.ndarray, fps: float = 60.0) -> np.ndarray:
    """(T,3) bias-free acceleration with the frames not ``ok`` filled. A busy hub marks bursts
    of frames missing: counting them as zero acceleration shortens the velocity along the
    step phases they fall in and turns the heading (10 % of frames missing in bursts put a
    wrist 4 deg off, 20 % over 9 deg); interpolated, a burst of a few frames costs only the
    acceleration's detail within it. A stream that stalls for longer than LONG_GAP_S (a
    pseudo-terminal waiting for a core) is another matter: the line between its edges'
    accelerations, a step's peaks apart, integrates to a velocity change of metres a
    second (a 1 s gap put a wrist 23-32 deg off). There the velocity is held instead (zero
    acceleration): a walk's speed changes little over a second, and what it does change
    stays along the walk, so its heading keeps (1.1 deg)."""
    if ok.all():
        return a
    t = np.arange(len(a))
    out = np.stack([np.interp(t, t[ok], a[ok, j]) for j in range(a.shape[1])], axis=-1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], (~ok).astype(np.int8), [0]])))
    for i, j in zip(edges[::2], edges[1::2]):  # runs of missing frames [i, j)
        if j - i > LONG_GAP_S * fps:
            out[i:j] = 0.0
    return out


def velocity(a: np.ndarray, fps: float) -> np.ndarray:
    """(T,3) velocity from acceleration with v(0) = v(end) = 0: the drift a constant bias
    adds is linear in time, and removing the line through the end value removes it."""
    v = np.cumsum(a, axis=0) / fps
    ramp = np.linspace(0.0, 1.0, len(v))[:, None]
    return v - ramp * v[-1]


def walk_displacements(a_G: np.ndarray, present: np.ndarray, fps: float, walk: tuple[int, int],
                       bias: tuple[int, int], turn: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per sensor, the horizontal displacement over frames ``walk`` (still at both ends) in
    its own reference frame (S,2), and the mean horizontal velocity of each third of the
    moving frames (S,3,2). a_G (T,S,3) free acceleration in G; ``bias`` a still window whose
    mean acceleration is the bias; ``turn`` (T,) the subject's turn since the stand (rad)."""
    S = a_G.shape[1]
    n0, n1 = bias
    w0, w1 = walk
    disp = np.full((S, 2), np.nan)
    thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        ok_still = present[n0:n1, k] & np.all(np.isfinite(a_G[n0:n1, k]), -1)
        seg = a_G[w0:w1, k]
        ok = present[w0:w1, k] & np.all(np.isfinite(seg), -1)
        if ok_still.sum() < 2 or ok.mean() < MIN_PRESENT:
            continue
        a = fill_gaps(seg - a_G[n0:n1, k][ok_still].mean(0), ok, fps)
        v = turn_back(velocity(a, fps)[:, :2], None if turn is None else np.nan_to_num(turn[w0:w1]))
        disp[k] = v.sum(0) / fps
        moving = v[np.linalg.norm(v, axis=-1) > MOVING_M_S]
        if len(moving) >= 3:
            for j, part in enumerate(np.array_split(moving, 3)):
                thirds[k, j] = part.mean(0)
    return disp, thirds


def swing_forward(quat: np.ndarray, present: np.ndarray, fps: float, window: tuple[int, int],
                  turn: np.ndarray | None = None, frames: np.ndarray | None = None,
                  axis: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Per sensor, the forward direction (S,2) in its reference frame from its swing axis,
    and the same from each third of the frames (S,3,2) (module docstring). ``turn`` (T,)
    the subject's turn since the stand (rad), ``frames`` (T,) bool: only these count (the
    walking ones of a log). ``axis``: the principal axis of the rate, signed by the peaks
    of the whole (``heading.axis_forward``), for logs whose walks differ in pace."""
    a, b = window
    S = quat.shape[1]
    fwd = np.full((S, 2), np.nan)
    thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        ok = present[a:b, k] & np.all(np.isfinite(quat[a:b, k]), -1)
        if ok.mean() < MIN_PRESENT:
            continue
        R = quat_to_matrix(np.where(ok[:, None], quat[a:b, k], [1.0, 0, 0, 0]))
        w = so3_log(R[1:] @ np.swapaxes(R[:-1], -1, -2))[:, :2] * fps  # world-frame rate, horizontal
        use = ok[1:] & ok[:-1]
        if frames is not None:
            use &= frames[a + 1:b]
        if turn is not None:
            use &= np.isfinite(turn[a + 1:b])
            w = turn_back(w, np.nan_to_num(turn[a + 1:b]))
        w = w[use]
        if len(w) < MIN_SWING_FRAMES:
            continue
        fwd[k] = axis_forward(w) if axis else peak_forward(w)
        for j, part in enumerate(np.array_split(w, 3)):
            thirds[k, j] = axis_forward(part, w) if axis else peak_forward(part)
    return fwd, thirds


def pick_direction(sites: Sequence[str], disp: np.ndarray, disp_thirds: np.ndarray, swing: np.ndarray,
                   swing_thirds: np.ndarray, swing_sites: Sequence[str] = SWING_SEGMENTS,
                   ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per sensor the forward (S,2) its thirds agree on best, their spread (S,) deg, and
    where it came from ("displacement", "swing axis"): a thigh or shank has both witnesses,
    the others only their displacement."""
    direction = np.array(disp, float, copy=True)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a sensor without a walk: NaN, as it should
        spread = np.nanmax(angle_between_2d(disp_thirds, disp[:, None, :]), axis=1)
    source = ["displacement"] * len(sites)
    for k, s in enumerate(sites):
        if s not in swing_sites or not np.isfinite(swing[k]).all():
            continue
        sw_spread = float(np.nanmax(angle_between_2d(swing_thirds[k], swing[k][None])))
        if not spread[k] <= sw_spread:  # the swing's thirds agree better (or the walk gave nothing)
            direction[k], spread[k], source[k] = swing[k], sw_spread, "swing axis"
    return direction, spread, source


# ------------------------------------------------------------------ logs: any walking, with turns


def still_frames(rate: np.ndarray, present: np.ndarray, fps: float) -> np.ndarray:
    """(T,) bool: every present sensor turns slower than STILL_DEG_S, for MIN_STILL_S at least."""
    g = np.rad2deg(np.linalg.norm(np.nan_to_num(np.asarray(rate, float)), axis=-1))
    still = ~np.any((g > STILL_DEG_S) & present, axis=1)
    out = np.zeros_like(still)
    n = int(round(MIN_STILL_S * fps))
    i = 0
    while i < len(still):
        if still[i]:
            j = i
            while j < len(still) and still[j]:
                j += 1
            if j - i >= n:
                out[i:j] = True
            i = j
        else:
            i += 1
    return out


def count_steps(rate: np.ndarray, ok: np.ndarray, fps: float) -> int:
    """Swing peaks of one leg segment: its rate above STEP_DEG_S, peaks 0.4 s apart at least."""
    g = np.rad2deg(np.linalg.norm(np.nan_to_num(rate), axis=-1)) * ok
    above = g > STEP_DEG_S
    starts = np.flatnonzero(above[1:] & ~above[:-1]) + 1
    gap = int(0.4 * fps)
    n, last = 0, -gap
    for s in starts:
        if s - last >= gap:
            n, last = n + 1, s
    return n


@dataclass
class GaitHeadings:
    """What the log's gait said of each sensor's heading (arrays over the sites)."""

    sites: tuple[str, ...]
    forward: np.ndarray  # (S,2) forward in the sensor's frame G; NaN where gait did not say
    spread_deg: np.ndarray  # (S,) largest disagreement of a third with the whole
    source: list[str]  # "swing axis", "displacement" or why there is none
    path_m: np.ndarray  # (S,) length of the turned-back displacement over the walking
    steps: int  # swing peaks of the leg segment with most
    extra: dict = field(default_factory=dict)

    @property
    def walking(self) -> bool:
        return self.steps >= MIN_STEPS


def gait_headings(sites: Sequence[str], quat: np.ndarray, rate: np.ndarray, present: np.ndarray, fps: float,
                  still: slice, free_acc: np.ndarray | None = None, acc: np.ndarray | None = None) -> GaitHeadings:
    """Each sensor's forward in its own frame from the walking in a log that starts with a
    still stand (``still``): leg segments from their swing axis or displacement, the others
    from their displacement between two still moments, each frame turned back by the
    subject's turn since the stand (module docstring). quat (T,S,4) R_GS, rate (T,S,3)
    rad/s in the sensor frame, present (T,S)."""
    sites = tuple(sites)
    quat = np.asarray(quat, float)
    T, S = quat.shape[:2]
    ok = np.all(np.isfinite(quat), axis=-1) & np.asarray(present, bool)
    R = quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))
    legs = [k for k, s in enumerate(sites) if s in SWING_SEGMENTS]
    steps = max((count_steps(rate[:, k], ok[:, k], fps) for k in legs), default=0)
    def turn_of(k: int) -> np.ndarray:
        return heading_change(R[:, k], ok[:, k], still_mean(R[:, k], ok[:, k], still))

    anchor = next((sites.index(s) for s in ("pelvis", "torso") if s in sites and ok[still, sites.index(s)].any()),
                  None)
    turn = turn_of(anchor) if anchor is not None else None
    moving = ~still_frames(rate, ok, fps)
    moving[still] = False
    straight = moving & _not_turning(turn, fps)  # a leg pivoting in a turn swings about no lateral axis
    swing = np.full((S, 2), np.nan)
    swing_thirds = np.full((S, 3, 2), np.nan)
    for k in legs:
        own = turn if turn is not None else turn_of(k)
        f, th = swing_forward(quat[:, k:k + 1], ok[:, k:k + 1], fps, (0, T), own, straight, axis=True)
        swing[k], swing_thirds[k] = f[0], th[0]
    # displacement over each stretch between still moments after the stand, summed
    a_G = _free_acc_G(quat, free_acc, acc)
    disp = np.zeros((S, 2))
    parts: list[list[np.ndarray]] = [[] for _ in range(S)]
    long_bouts = [(a, b) for a, b in _bouts(~moving, 0) if (b - a) / fps > MAX_BOUT_S]
    bouts = [(a, b) for a, b in _bouts(~moving, 0) if (b - a) / fps <= MAX_BOUT_S]
    for a, b in bouts:
        d, th = walk_displacements(a_G, ok, fps, (a, b), (still.start, still.stop), turn)
        disp += np.nan_to_num(d)
        for k in range(S):
            if np.isfinite(th[k]).all():
                parts[k].append(th[k])
    if turn is None:
        disp[[k for k in range(S) if k not in legs]] = np.nan  # a turning log without a trunk says nothing
    path = np.linalg.norm(disp, axis=-1)
    disp_thirds = np.full((S, 3, 2), np.nan)
    for k in range(S):
        if parts[k]:
            disp_thirds[k] = np.sum(parts[k], axis=0)
    short = ~(path >= MIN_WALK_M)
    disp[short] = np.nan
    for k in legs:  # a thigh swings back about as fast as forward: where the sensor's path says, it signs the axis
        if np.isfinite(disp[k]).all() and np.isfinite(swing[k]).all() and float(disp[k] @ swing[k]) < 0:
            swing[k], swing_thirds[k] = -swing[k], -swing_thirds[k]
    direction, spread, source = pick_direction(sites, disp, disp_thirds, swing, swing_thirds)
    for k in range(S):
        if not np.isfinite(direction[k]).all():
            source[k] = (f"no swing, and a path of {path[k]:.1f} m (at least {MIN_WALK_M:g} m needed)"
                         if bouts else f"no swing, and no walk between two still moments under {MAX_BOUT_S:g} s"
                         + (f" (its {max(b - a for a, b in long_bouts) / fps:.0f} s walk would drift)"
                            if long_bouts else ""))
    unsure = spread > UNSURE_DEG
    for k in np.flatnonzero(unsure):
        source[k] = f"its walk's thirds disagree by {spread[k]:.0f} deg ({source[k]})"
    direction[unsure] = np.nan
    return GaitHeadings(sites, direction, spread, source, path, steps, {"bouts": bouts})


def _not_turning(turn: np.ndarray | None, fps: float) -> np.ndarray | bool:
    """(T,) bool: the subject turns slower than TURN_DEG_S (over 0.5 s); True without a trunk sensor."""
    if turn is None:
        return True
    ok = np.isfinite(turn)
    if ok.sum() < 2:
        return ok
    t = np.arange(len(turn))
    yaw = np.unwrap(np.interp(t, t[ok], turn[ok]))
    h = max(1, int(0.25 * fps))
    rate = np.degrees(np.abs(yaw[np.minimum(t + h, len(t) - 1)] - yaw[np.maximum(t - h, 0)])) * fps / (2 * h)
    return ok & (rate < TURN_DEG_S)


def _bouts(still: np.ndarray, start: int) -> list[tuple[int, int]]:
    """Stretches of motion after ``start`` with still frames at both ends, as
    (first still frame before, first still frame after + 1) so velocity is zero at both."""
    out = []
    T = len(still)
    i = start
    while i < T:
        if still[i]:
            i += 1
            continue
        a = i - 1
        while i < T and not still[i]:
            i += 1
        if a >= 0 and i < T:
            out.append((a, i + 1))
    return out


def consensus_forward(forward: np.ndarray, min_agree: int = 2) -> np.ndarray | None:
    """(2,) the forward most sensors agree on: the mean of the largest group of estimates
    within WARN_DEG of one of them (robust to a sensor far off); None when fewer than
    ``min_agree`` agree."""
    f = forward[np.all(np.isfinite(forward), axis=-1)]
    if not len(f):
        return None
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    close = angle_between_2d(f[:, None], f[None]) < WARN_DEG
    best = int(np.argmax(close.sum(1) - 1e-3 * angle_between_2d(f[:, None], f[None]).sum(1)))
    if close[best].sum() < min_agree:
        return None
    m = f[close[best]].mean(0)
    return m / np.linalg.norm(m)


__all__ = ["GaitHeadings", "MIN_WALK_M", "SWING_SEGMENTS", "WARN_DEG", "angle_between_2d", "consensus_forward",
           "fill_gaps", "gait_headings", "heading_change", "pick_direction", "signed_angle_deg", "still_frames",
           "swing_forward", "turn_back", "velocity", "walk_displacements"]
