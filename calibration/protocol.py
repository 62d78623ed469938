"""The calibration protocol a subject follows, and a simulator of it for tests and the demo.

Protocol (timings in ``Protocol``):
1. ``table``: the sensors lie on a table in the reference orientation (x forward, y
   left, z up, forward = where the subject will face), untouched;
2. ``strap``: they are picked up and strapped on (the sensors move; nothing is measured);
3. ``tpose``: the subject holds the T-pose, still;
4. ``blend``: the subject moves from the T-pose into the activity, which follows.

``synthesize_session`` builds the signals a suit would send during all of this: the body
motion (T-pose hold, blend, activity) goes through ``inference.synthesis.synthesize``
with the noise model (mounting rotation and reference-frame heading included), and the
table and strap phases are then written over the first seconds with the *same* sensors'
heading, biases and noise, but the sensor orientations of the protocol. The strap phase
is a smooth, gyro-consistent path (an AHRS on the receiving side integrates the gyro, so
a jump in orientation without a matching rate would be a lie the DualSense path notices).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from inference.body.body import contact_points, forward_kinematics, tpose
from inference.body.conventions import rot_z
from inference.body.motion import Motion
from inference.body.rotations import matrix_about_axis, matrix_to_quat, quat_slerp, quat_to_matrix, so3_exp
from inference.body.skeleton import SITES
from inference.signals.resample import moving_average
from inference.signals.site_signals import SiteSignals
from inference.signals.synthesis import GRAVITY, NoiseModel, angular_velocity, synthesize

from .live import CalibrationSchedule


@dataclass
class Protocol:
    """Durations (s) of the protocol phases; ``margin`` is cut from both ends of each still
    phase when calibrating, so clock offsets between devices and the hub's latency never
    put a moving frame inside a window."""

    table: float = 3.0
    strap: float = 1.5
    tpose: float = 3.0
    blend: float = 1.0
    margin: float = 0.4

    @property
    def prefix(self) -> float:
        """Seconds before the activity starts."""
        return self.table + self.strap + self.tpose + self.blend

    @property
    def calibrated_at(self) -> float:
        """Seconds after the start when the T-pose window closes."""
        return self.table + self.strap + self.tpose - self.margin

    def schedule(self) -> CalibrationSchedule:
        m = self.margin
        return CalibrationSchedule(
            world_start=m, world_seconds=self.table - 2 * m,
            tpose_start=self.table + self.strap + m, tpose_seconds=self.tpose - 2 * m,
        )

    @classmethod
    def fitted(cls, total: float, fraction: float = 0.6) -> Protocol:
        """The default protocol, or a proportionally shorter one that leaves at least
        ``1 - fraction`` of a ``total``-second session for the activity (short demo
        runs); still windows never shorter than 0.5 s."""
        p = cls()
        if p.prefix <= fraction * total:
            return p
        k = max(fraction * total / p.prefix, 2.1 / p.prefix)
        return cls(table=p.table * k, strap=p.strap * k, tpose=p.tpose * k, blend=p.blend * k,
                   margin=min(p.margin * k, 0.2))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _slerp_R(R0: np.ndarray, R1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(T, ..., 3, 3) rotations from R0 to R1 (..., 3, 3) at weights w (T,)."""
    q0, q1 = matrix_to_quat(R0), matrix_to_quat(R1)
    wq = w.reshape((-1,) + (1,) * (q0.ndim - 1))
    return quat_to_matrix(quat_slerp(np.broadcast_to(q0, (len(w),) + q0.shape),
                                     np.broadcast_to(q1, (len(w),) + q1.shape), wq))


def velocity_at(root: np.ndarray, fps: float, end: bool = False) -> np.ndarray:
    """The root's velocity (m/s) over the first (or, ``end``, the last) three frames."""
    r = root[-3:] if end else root[:3]
    return (r[-1] - r[0]) * fps / max(len(r) - 1, 1)


def root_blend(p0: np.ndarray, v0: np.ndarray, p1: np.ndarray, v1: np.ndarray, n: int, fps: float) -> np.ndarray:
    """``n`` root positions strictly between (p0, moving at v0) and (p1, moving at v1), a cubic Hermite
    path: the position and the velocity join at both ends. A blend whose weights rise from 0 to 1 with
    zero slope stops the root at each end, so a subject standing still went to walking speed within
    one 60 Hz sample: a single pelvis free acceleration of 113 m/s^2 at every simulated activity's start
    (the demo's signal plot showed it). Callers place the standing end ``v * duration / 2`` behind (or
    ahead of) the moving one, so the speed ramps evenly over the blend."""
    s = ((np.arange(n) + 1) / (n + 1))[:, None]
    D = (n + 1) / fps
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * p0 + h10 * D * v0 + h01 * p1 + h11 * D * v1


def _ramp_offset(v: np.ndarray, n: int, fps: float) -> np.ndarray:
    """How far (x, y, 0) a body moving at ``v`` covers while its speed ramps evenly from 0 over a blend of
    ``n`` frames: where its standing end goes, behind the moving end (or ahead, after it)."""
    D = (n + 1) / fps
    return np.array([v[0], v[1], 0.0]) * D / 2


def tpose_standing(motion_body, n: int, fps: float, xy: tuple[float, float] = (0.0, 0.0)) -> Motion:
    """``n`` frames of an exactly still T-pose, feet on the floor, facing +X."""
    R = tpose(n)
    j = forward_kinematics(R[:1], np.zeros(3), motion_body.offsets)
    z = -float(contact_points(R[:1], j, motion_body)[..., 2].min())
    root = np.tile([xy[0], xy[1], z], (n, 1))
    return Motion(rot=R, root=root, fps=fps, body=motion_body, name="tpose")


def session_motion(activity: Motion, protocol: Protocol | None = None) -> Motion:
    """The subject's body motion over a whole session at the activity's rate: T-pose held
    through the table, strap and T-pose phases, a smooth blend, then ``activity`` (which
    should face +X at its start: X is the subject's forward at calibration)."""
    p = protocol or Protocol()
    fps = activity.fps
    n_hold = int(round((p.table + p.strap + p.tpose) * fps))
    n_blend = max(int(round(p.blend * fps)), 1)
    v1 = velocity_at(activity.root, fps)
    start = activity.root[0] - _ramp_offset(v1, n_blend, fps)  # the subject stands where the ramp begins
    hold = tpose_standing(activity.body, n_hold + n_blend, fps, (float(start[0]), float(start[1])))
    w = _smoothstep((np.arange(n_blend) + 1) / (n_blend + 1))
    Rb = _slerp_R(hold.rot[0], activity.rot[0], w)
    rb = root_blend(hold.root[0], np.zeros(3), activity.root[0], v1, n_blend, fps)
    rot = np.concatenate([hold.rot[:n_hold], Rb, activity.rot])
    root = np.concatenate([hold.root[:n_hold], rb, activity.root])
    meta = dict(activity.meta or {})
    meta["protocol"] = p
    meta["activity_start_frame"] = n_hold + n_blend
    return replace(activity, rot=rot, root=root, name=f"session_{activity.name}", meta=meta)


def synthesize_session(
    activity: Motion,
    protocol: Protocol | None = None,
    noise: NoiseModel | None = None,
    rng: np.random.Generator | int | None = None,
    sites: tuple[str, ...] | list[str] = SITES,
    R_known: np.ndarray | None = None,
) -> tuple[SiteSignals, Motion]:
    """Signals of a whole session (see module docstring) and the body-motion truth (60 Hz).

    ``meta`` of the signals carries synthesis's R_SB / R_WG (what calibration must
    recover), ``protocol`` and ``activity_start`` (s)."""
    p = protocol or Protocol()
    rng = np.random.default_rng(rng)
    truth = session_motion(activity.resample(60.0), p)
    sig = synthesize(truth, noise=noise, rng=rng, sites=tuple(sites))
    nz = noise or NoiseModel()
    fps = sig.fps
    n_table = int(round(p.table * fps))
    n_strap = int(round(p.strap * fps))
    n_pre = n_table + n_strap
    S = len(sig.sites)
    Rk = np.eye(3) if R_known is None else np.asarray(R_known, float)
    R_WG = sig.meta["R_WG"]
    R_BS = np.swapaxes(sig.meta["R_SB"], -1, -2)
    # world orientation of each sensor: table, strap path (slerp plus a lift-and-turn
    # wobble), then on the bone (T-pose: R_WB = I, so R_WS = R_BS) for a few frames of overlap
    s = _smoothstep((np.arange(n_strap) + 0.5) / n_strap)
    R_path = _slerp_R(np.broadcast_to(Rk, (S, 3, 3)), R_BS, s)
    axis = rng.normal(size=(S, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    wob = np.sin(np.pi * s)[:, None] * np.deg2rad(40.0)
    R_path = matrix_about_axis(np.broadcast_to(axis, (n_strap, S, 3)), wob) @ R_path
    R_WS = np.concatenate([np.broadcast_to(Rk, (n_table, S, 3, 3)), R_path, np.broadcast_to(R_BS, (2, S, 3, 3))])
    gyro = angular_velocity(R_WS, fps)[:n_pre]
    R_WS = R_WS[:n_pre]
    a_W = np.zeros((n_pre, S, 3))  # sensors carried gently: translation neglected
    f = (np.swapaxes(R_WS, -1, -2) @ (a_W - GRAVITY)[..., None])[..., 0] + sig.meta["acc_bias"]
    g = gyro + sig.meta["gyro_bias"]
    if nz.acc_white > 0:
        f = f + rng.normal(size=f.shape) * nz.acc_white
    if nz.gyro_white > 0:
        g = g + rng.normal(size=g.shape) * nz.gyro_white
    R_GS = np.swapaxes(R_WG, -1, -2)[None] @ R_WS
    if nz.ori_white_deg > 0:
        R_GS = so3_exp(rng.normal(size=(n_pre, S, 3)) * np.deg2rad(nz.ori_white_deg)) @ R_GS
    free_raw = sig.meta["free_acc_raw"].copy()
    free_raw[:n_pre] = (R_GS @ f[..., None])[..., 0] + GRAVITY if noise is not None else a_W
    quat = sig.quat.copy()
    quat[:n_pre] = matrix_to_quat(R_GS)
    sf, gy = sig.specific_force.copy(), sig.gyro.copy()
    sf[:n_pre], gy[:n_pre] = f, g
    meta = dict(sig.meta)
    meta.update(free_acc_raw=free_raw, protocol=p, activity_start=truth.meta["activity_start_frame"] / fps,
                R_known=Rk)
    out = replace(sig, quat=quat, free_acc=moving_average(free_raw), specific_force=sf, gyro=gy, meta=meta)
    return out, truth


@dataclass
class WalkProtocol:
    """Durations (s) of the table-free protocol (``calibration.walk``): N-pose held still,
    a walk forward, standing still, then a blend into the activity. ``walk`` is the
    simulated subject's walking time; a real subject's is whatever they take."""

    npose: float = 7.0  # the guided steps: 3 s countdown, 3 s hold, a margin
    walk: float = 4.0
    stand: float = 3.5  # 1 s settling after the walk, 1.5 s hold, a margin
    blend: float = 1.0

    @property
    def prefix(self) -> float:
        return self.npose + self.walk + self.stand + self.blend


def _npose_standing(body, n: int, fps: float, xy: tuple[float, float], heading: float = 0.0) -> Motion:
    from inference.body.body import npose_rotations

    Rh = rot_z(heading)
    R = Rh @ npose_rotations(n)
    j = forward_kinematics(R[:1], np.zeros(3), body.offsets)
    z = -float(contact_points(R[:1], j, body)[..., 2].min())
    return Motion(rot=R, root=np.tile([xy[0], xy[1], z], (n, 1)), fps=fps, body=body, name="npose")


def _blend(a: Motion, b_rot: np.ndarray, n: int) -> np.ndarray:
    """``n`` orientations from the last frame of ``a`` to ``b_rot`` (the root's path: ``root_blend``)."""
    return _slerp_R(a.rot[-1], b_rot, _smoothstep((np.arange(n) + 1) / (n + 1)))


def walk_session_motion(activity: Motion, walk: Motion, protocol: WalkProtocol | None = None) -> Motion:
    """The subject's body motion for the table-free protocol at the activity's rate:
    N-pose, blend into ``walk`` (which faces +X, from the origin), stand in the N-pose
    where the walk ended, then ``activity`` moved to start there."""
    p = protocol or WalkProtocol()
    fps = activity.fps
    walk = walk.resample(fps)
    body = activity.body
    n_np = int(round(p.npose * fps))
    n_bl = max(int(round(0.5 * fps)), 1)
    n_walk = int(round(p.walk * fps))
    w = walk.rot[:n_walk], walk.root[:n_walk]
    # each blend between standing and moving joins the root's velocity too (``root_blend``): the standing
    # body is placed where an even ramp of the speed over the blend puts it
    v_in = velocity_at(w[1], fps)
    at = w[1][0] - _ramp_offset(v_in, n_bl, fps)
    start = _npose_standing(body, n_np, fps, (float(at[0]), float(at[1])))
    r_in = _blend(start, w[0][0], n_bl)
    p_in = root_blend(start.root[-1], np.zeros(3), w[1][0], v_in, n_bl, fps)
    seg = Motion(rot=np.concatenate([start.rot, r_in, w[0]]), root=np.concatenate([start.root, p_in, w[1]]),
                 fps=fps, body=body)
    v_out = velocity_at(w[1], fps, end=True)
    at = w[1][-1] + _ramp_offset(v_out, n_bl, fps)
    end_xy = (float(at[0]), float(at[1]))
    stand = _npose_standing(body, int(round(p.stand * fps)), fps, end_xy)
    r_st = _blend(seg, stand.rot[0], n_bl)
    p_st = root_blend(w[1][-1], v_out, stand.root[0], np.zeros(3), n_bl, fps)
    n_act_bl = max(int(round(p.blend * fps)), 1)
    v_act = velocity_at(activity.root, fps)
    act_at = np.array([end_xy[0], end_xy[1], 0.0]) + _ramp_offset(v_act, n_act_bl, fps)
    act_root = activity.root - np.array([activity.root[0, 0] - act_at[0], activity.root[0, 1] - act_at[1], 0.0])
    pre = Motion(rot=np.concatenate([seg.rot, r_st, stand.rot]), root=np.concatenate([seg.root, p_st, stand.root]),
                 fps=fps, body=body)
    r_ab = _blend(pre, activity.rot[0], n_act_bl)
    p_ab = root_blend(pre.root[-1], np.zeros(3), act_root[0], v_act, n_act_bl, fps)
    rot = np.concatenate([pre.rot, r_ab, activity.rot])
    root = np.concatenate([pre.root, p_ab, act_root])
    meta = dict(activity.meta or {})
    walk_start = n_np
    walk_end = n_np + n_bl + n_walk + n_bl
    meta.update(protocol=p, activity_start_frame=pre.n_frames + n_act_bl,
                walk_windows=((0, n_np), (walk_start, walk_end), (walk_end, pre.n_frames)))
    return replace(activity, rot=rot, root=root, name=f"session_{activity.name}", meta=meta)


def synthesize_walk_session(
    activity: Motion,
    walk: Motion,
    protocol: WalkProtocol | None = None,
    noise: NoiseModel | None = None,
    rng: np.random.Generator | int | None = None,
    sites: tuple[str, ...] | list[str] = SITES,
) -> tuple[SiteSignals, Motion]:
    """Signals a suit sends while its wearer follows the table-free protocol and then the
    activity, and the body-motion truth (60 Hz). Each sensor keeps its own heading
    reference and mounting (the noise model's), which is what the walk must find.
    ``meta``: synthesis's R_SB / R_WG, ``protocol``, ``activity_start`` (s) and
    ``walk_windows`` (frame ranges of N-pose, walk, stand at 60 Hz)."""
    p = protocol or WalkProtocol()
    truth = walk_session_motion(activity.resample(60.0), walk, p)
    sig = synthesize(truth, noise=noise, rng=rng, sites=tuple(sites))
    meta = dict(sig.meta)
    meta.update(protocol=p, activity_start=truth.meta["activity_start_frame"] / sig.fps,
                walk_windows=truth.meta["walk_windows"])
    return replace(sig, meta=meta), truth
