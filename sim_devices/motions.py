"""Procedural human motions for tests, demos and smoke-training, with no data files.

Kinds: walk, jog, squat, lunge, jump, arm_raises, stand, tpose, npose, walk_trial. Each is built on
our body (``Body.from_height``) and written as an AMASS-format .npz
(``write_amass_npz``), so the same AMASS loader that reads real data reads these.

How plausibility is obtained:
- walk/jog: periodic joint-angle curves shaped like normative gait data (hip flexion
  sinusoid, a small stance knee flexion and a large swing knee flexion, ankle rocker
  pattern), pelvis yaw/roll, trunk counter-rotation, arm swing opposite the legs. The
  root is then *derived*, not prescribed: horizontally it moves so that the lowest foot
  point does not slide (the stance foot rolls heel to toe), vertically so that this point
  is on the floor (which gives the pelvis bob). The stride amplitude sets the step
  length; the cadence is chosen so the mean speed equals the requested speed. Jogging
  adds ballistic flight phases (vertical bounce while no foot is loaded).
- squat, lunge, jump: the pelvis and feet follow smooth trajectories and the legs come
  from planar two-link inverse kinematics, so planted feet stay exactly planted (a jump's
  flight follows a parabola with g = 9.81).
- arm raises, standing: lower body still, upper body motion on top.
- tpose/npose holds: exactly still (zero acceleration: the physics tests use them).
- walk_trial: a lab's walking trial, which does not repeat itself: standing still, setting
  off, walking with 180 deg turns (alternately left and right, shorter and slower steps
  while turning) and a change to a brisker pace halfway through the walking
  (``walk_trial_profile``). The walk's curves with the gait's excursions, cadence and
  heading varied over time.

``speed`` is m/s for walk/jog (defaults 1.3 and 2.8) and a tempo factor (1 = normal) for
the others. A seed varies amplitudes slightly (+-8%) and the start phase; the heading is
+X unless ``heading_deg`` is given.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d

from inference.body.body import Body, contact_points, forward_kinematics, global_from_local
from inference.body.conventions import rot_z
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_matrix
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.loaders.amass_frames import global_to_amass_poses

KINDS: tuple[str, ...] = ("walk", "jog", "squat", "lunge", "jump", "arm_raises", "stand", "tpose", "npose",
                          "walk_trial")
DEFAULT_SPEED = {"walk": 1.3, "jog": 2.8, "walk_trial": 1.3}
G = 9.81
I = SEGMENT_INDEX  # noqa: E741  (short alias keeps the pose tables readable)


# --------------------------------------------------------------------------- rotation helpers
def _axis(a: np.ndarray, k: int) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    v = np.zeros(a.shape + (3,))
    v[..., k] = a
    return axis_angle_to_matrix(v)


def rx(a):  # noqa: D103
    return _axis(a, 0)


def ry(a):  # noqa: D103
    return _axis(a, 1)


rz = rot_z


def _bump(p: np.ndarray, centre: float, width: float) -> np.ndarray:
    """Periodic Gaussian bump on the gait phase p in [0, 1)."""
    d = (p - centre + 0.5) % 1.0 - 0.5
    return np.exp(-((d / width) ** 2))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class _Pose:
    """Local (parent-relative) rotations (T, 24, 3, 3), built up joint by joint."""

    L: np.ndarray

    @classmethod
    def identity(cls, T: int) -> _Pose:
        return cls(np.broadcast_to(np.eye(3), (T, N_SEGMENTS, 3, 3)).copy())

    def set(self, name: str, R: np.ndarray) -> None:
        self.L[:, I[name]] = R

    def globals(self) -> np.ndarray:
        return global_from_local(self.L)


# --------------------------------------------------------------------------- upper body
def _arms(pose: _Pose, swing_l, swing_r, elbow_l, elbow_r, down_l=1.36, down_r=1.36) -> None:
    """Arm angles (rad): `down` lowers the arm from the T-pose about the forward axis
    (pi/2 = hanging, 0 = T-pose, negative = above), `swing` moves it forward about the
    lateral axis (shoulder flexion), `elbow` flexes the forearm forward."""
    pose.set("l_upperarm", ry(-np.asarray(swing_l)) @ rx(-np.asarray(down_l)))
    pose.set("r_upperarm", ry(-np.asarray(swing_r)) @ rx(np.asarray(down_r)))
    pose.set("l_forearm", rz(-np.asarray(elbow_l)))
    pose.set("r_forearm", rz(np.asarray(elbow_r)))


def _trunk(pose: _Pose, lean, yaw=0.0, roll=0.0) -> None:
    """Spread a trunk lean (forward, rad), yaw and roll over spine1..3; neck/head take the
    yaw back so the gaze stays ahead."""
    lean, yaw, roll = (np.asarray(v, dtype=np.float64) for v in (lean, yaw, roll))
    for s in ("spine1", "spine2", "spine3"):
        pose.set(s, rz(yaw / 3) @ ry(lean / 3) @ rx(roll / 3))
    pose.set("neck", ry(-lean * 0.3))
    pose.set("head", ry(-lean * 0.2))


# --------------------------------------------------------------------------- geometry
@dataclass
class _Leg:
    l1: float  # thigh (hip->knee)
    l2: float  # shank (knee->ankle)
    ankle_h: float  # ankle joint height above the floor with the foot flat
    toe_fwd: float  # toe contact point ahead of the ankle (flat foot)
    toe_down: float  # toe contact point below the ankle (flat foot)


def _leg_geometry(body: Body) -> _Leg:
    R = np.broadcast_to(np.eye(3), (1, N_SEGMENTS, 3, 3))
    j = forward_kinematics(R, np.zeros(3), body.offsets)
    c = contact_points(R, j, body)[0]
    ankle = j[0, I["l_foot"]]
    return _Leg(
        l1=float(np.linalg.norm(body.offsets[I["l_shank"]])), l2=float(np.linalg.norm(body.offsets[I["l_foot"]])),
        ankle_h=float(ankle[2] - c[:2, 2].min()), toe_fwd=float(c[1, 0] - ankle[0]),
        toe_down=float(ankle[2] - c[1, 2]),
    )


def _ik(hip: np.ndarray, ankle: np.ndarray, leg: _Leg) -> tuple[np.ndarray, np.ndarray]:
    """Planar two-link IK in the sagittal (x, z) plane: forward angles from the downward
    vertical of thigh and shank (knee bending forward) that put the ankle at `ankle`."""
    d = ankle - hip
    D = np.clip(np.hypot(d[..., 0], d[..., 1]), 1e-6, (leg.l1 + leg.l2) * 0.9999)
    alpha = np.arctan2(d[..., 0], -d[..., 1])
    beta = np.arccos(np.clip((leg.l1**2 + D**2 - leg.l2**2) / (2 * leg.l1 * D), -1, 1))
    knee = np.pi - np.arccos(np.clip((leg.l1**2 + leg.l2**2 - D**2) / (2 * leg.l1 * leg.l2), -1, 1))
    thigh = alpha + beta
    return thigh, thigh - knee


def _legs_from_ik(pose: _Pose, pelvis_R: np.ndarray, thigh: dict, shank: dict, foot_pitch: dict) -> None:
    """Set local leg rotations from global sagittal angles (thigh/shank forward angles,
    foot pitch: positive = heel up), given the pelvis global orientation."""
    for s in ("l", "r"):
        Gt, Gs, Gf = ry(-thigh[s]), ry(-shank[s]), ry(foot_pitch[s])
        pose.set(f"{s}_thigh", np.swapaxes(pelvis_R, -1, -2) @ Gt)
        pose.set(f"{s}_shank", np.swapaxes(Gt, -1, -2) @ Gs)
        pose.set(f"{s}_foot", np.swapaxes(Gs, -1, -2) @ Gf)


def _ankle_for_heel_raise(toe_x: np.ndarray, pitch: np.ndarray, leg: _Leg) -> tuple[np.ndarray, np.ndarray]:
    """Ankle (x, z) with the toe contact point fixed at (toe_x, 0) and the foot pitched
    heel-up by `pitch` about it."""
    c, s = np.cos(pitch), np.sin(pitch)
    # toe point relative to the ankle in the foot frame: (toe_fwd, -toe_down); rotate by ry(pitch)
    tx = c * leg.toe_fwd - s * leg.toe_down
    tz = -s * leg.toe_fwd - c * leg.toe_down
    return toe_x - tx, -tz


# --------------------------------------------------------------------------- kinds
def _gait(T: int, fps: float, body: Body, speed: float, rng: np.random.Generator, run: bool,
          amplitude: np.ndarray | None = None, pace: np.ndarray | None = None,
          heading: np.ndarray | None = None) -> Motion:
    """Walk or jog. Optional per-frame profiles (T,): ``amplitude`` scales every gait
    excursion (0 = standing upright, 1 = the steady gait's), ``pace`` the cadence (1 = the
    one that gives ``speed``), ``heading`` (rad) turns the walker about the vertical; the
    root follows from the stance foot whatever they do."""
    t = np.arange(T) / fps
    v = 1.0 + rng.uniform(-0.08, 0.08, size=8)
    if run:
        hip_amp, hip_off = (0.42 + 0.05 * speed) * v[0], 0.12
        k_st, k_sw, k_sw_c = 0.55 * v[1], 1.65 * v[2], 0.7
        arm_amp, elbow0, lean = 0.45 * v[3], 1.45, 0.14
        yaw_amp, roll_amp = 0.12 * v[4], 0.04
    else:
        hip_amp, hip_off = (0.26 + 0.09 * speed) * v[0], 0.06
        k_st, k_sw, k_sw_c = 0.3 * v[1], 1.05 * v[2], 0.72
        arm_amp, elbow0, lean = (0.15 + 0.12 * speed) * v[3], 0.3, 0.04
        yaw_amp, roll_amp = 0.07 * v[4], 0.05

    def angles(p: np.ndarray, e) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        hip = e * (hip_off + hip_amp * np.cos(2 * np.pi * p))
        knee = e * (k_st * _bump(p, 0.17 if run else 0.14, 0.08) + k_sw * _bump(p, k_sw_c, 0.13))
        ankle = e * (0.17 * _bump(p, 0.42, 0.12) - 0.35 * _bump(p, 0.62, 0.06) + 0.06 * _bump(p, 0.85, 0.1)
                     - 0.08 * _bump(p, 0.05, 0.04))
        return hip, knee, ankle

    def build(phase: np.ndarray, e=1.0) -> tuple[np.ndarray, np.ndarray]:
        pl = phase % 1.0
        pr = (phase + 0.5) % 1.0
        n = phase.shape[0]
        pose = _Pose.identity(n)
        c = np.cos(2 * np.pi * phase)
        yaw = e * (-yaw_amp * c)
        pose.set("pelvis", rz(yaw) @ ry(np.full(n, lean * 0.5)) @ rx(e * (roll_amp * np.sin(2 * np.pi * phase))))
        for s, p in (("l", pl), ("r", pr)):
            hip, knee, ankle = angles(p, e)
            pose.set(f"{s}_thigh", ry(-hip))
            pose.set(f"{s}_shank", ry(knee))
            pose.set(f"{s}_foot", ry(-ankle))
            pose.set(f"{s}_toes", ry(e * (-0.4 * _bump(p, 0.6, 0.07))))
        _trunk(pose, np.full(n, lean * 0.5), yaw=-0.8 * yaw)
        swing_l = e * (-arm_amp * c)
        elbow_extra = 0.25 if not run else 0.15
        _arms(pose, swing_l, -swing_l, elbow0 + elbow_extra * np.maximum(swing_l, 0),
              elbow0 + elbow_extra * np.maximum(-swing_l, 0))
        R = pose.globals()
        j = forward_kinematics(R, np.zeros(3), body.offsets)
        return R, contact_points(R, j, body)

    duty = 0.38 if run else 0.5  # each foot anchors the body from its strike for this phase fraction

    def anchor_velocity(phase: np.ndarray, cp: np.ndarray, dt: float) -> np.ndarray:
        """Horizontal root velocity that keeps the anchoring stance foot's lowest point
        still; in flight (jog) interpolated between the neighbouring stance velocities."""
        pl, pr = phase % 1.0, (phase + 0.5) % 1.0
        v = np.gradient(cp, dt, axis=0)
        n = phase.shape[0]
        rows = np.arange(n)
        lo_l = np.argmin(cp[:, :2, 2], axis=-1)
        lo_r = 2 + np.argmin(cp[:, 2:, 2], axis=-1)
        left, right = pl < duty, (pr < duty) & ~(pl < duty)
        out = np.full((n, 2), np.nan)
        out[left] = -v[rows[left], lo_l[left], :2]
        out[right] = -v[rows[right], lo_r[right], :2]
        ok = ~np.isnan(out[:, 0])
        for k in range(2):
            out[~ok, k] = np.interp(rows[~ok], rows[ok], out[ok, k])
        return out

    # one cycle, finely sampled, measures the stride length these angles produce
    n_cyc = 400
    ph = np.arange(n_cyc) / n_cyc
    _, cp = build(ph)
    stride = float(anchor_velocity(ph, cp, 1.0 / n_cyc)[:, 0].mean())
    cadence = speed / max(stride, 1e-3)
    if pace is None:
        phase = rng.uniform() + cadence * t
    else:
        phase = rng.uniform() + cadence * np.concatenate([[0.0], np.cumsum(pace[:-1])]) / fps
    R, cp = build(phase, 1.0 if amplitude is None else amplitude)
    if heading is not None:
        # the body turns about the root (FK was from a root at the origin), so the contact
        # points turn with it and the stance foot's anchoring holds in the world
        Rh = rz(heading)
        R = Rh[:, None] @ R
        cp = np.einsum("tij,tkj->tki", Rh, cp)
    vel = anchor_velocity(phase, cp, 1.0 / fps)
    # the anchor (lowest point, stance foot) switches at heel-to-toe roll and at foot strike,
    # which puts kinks into the derived root path and spikes of tens of m/s^2 into the pelvis
    # acceleration; short Gaussians (35 ms horizontal, 60 ms vertical) remove most of them
    # at the cost of some stance-foot slide (a trade-off: see docs/motion_data.md)
    sigma = 0.06 * fps
    vel = gaussian_filter1d(vel, 0.035 * fps, axis=0, mode="nearest")
    root = np.zeros((T, 3))
    root[:, :2] = np.cumsum(vel, axis=0) / fps
    root[:, :2] -= root[:1, :2]
    root[:, 2] = gaussian_filter1d(-cp[..., 2].min(-1), sigma, mode="nearest")
    if run:
        # flight: while no foot is below its stance height the body is ballistic; add a
        # vertical bounce that peaks mid-flight (two flights per stride)
        q = (2 * phase) % 1.0  # 0 = a foot strikes
        flight = q > 2 * duty
        tf = (1 - 2 * duty) / (2 * cadence)  # flight duration
        tau = np.where(flight, (q - 2 * duty) / (2 * cadence), 0.0)
        root[:, 2] += np.where(flight, 0.5 * G * tau * (tf - tau), 0.0)
    return Motion(rot=R, root=root, fps=fps, body=body)


def _stand_base(T: int, body: Body, pose: _Pose) -> tuple[np.ndarray, np.ndarray]:
    R = pose.globals()
    j = forward_kinematics(R, np.zeros(3), body.offsets)
    cp = contact_points(R, j, body)
    root = np.zeros((T, 3))
    root[:, 2] = -cp[..., 2].min(-1)
    return R, root


def walk_trial_profile(t: np.ndarray) -> dict[str, np.ndarray]:
    """The shape of a ``walk_trial`` over the times ``t`` (s, from 0): ``amplitude`` of the
    gait's excursions (0 standing), ``pace`` (cadence factor), ``heading`` (rad) per frame,
    and the trial's marks (s): ``stand_s`` (standing still until then), ``walk_s`` (steady
    walking from then), ``brisk_s`` (the brisker pace reached from then), ``turns_s`` (each
    turn's start; a turn takes ``TRIAL_TURN_S``). Durations shrink for short clips."""
    t = np.asarray(t, dtype=np.float64)
    dur = float(t[-1]) if t.size else 0.0
    stand = min(TRIAL_STAND_S, 0.15 * dur)
    ramp = min(1.0, 0.1 * dur)
    walk0 = stand + ramp
    amp = _smoothstep((t - stand) / max(ramp, 1e-9))
    pace = np.ones_like(t)
    heading = np.zeros_like(t)
    brisk = walk0 + 0.5 * (dur - walk0)
    up = _smoothstep((t - brisk) / 2.0)
    amp = amp * (1.0 + 0.08 * up)
    pace = pace * (1.0 + 0.2 * up)
    turns = []
    t_turn = walk0 + TRIAL_STRAIGHT_S
    sign = 1.0
    while t_turn + TRIAL_TURN_S < dur - 1.0:
        turns.append(t_turn)
        u = (t - t_turn) / TRIAL_TURN_S
        heading = heading + sign * np.pi * _smoothstep(u)
        dip = np.sin(np.pi * np.clip(u, 0.0, 1.0))  # shorter, slower steps while turning
        amp = amp * (1.0 - 0.15 * dip)
        pace = pace * (1.0 - 0.1 * dip)
        sign = -sign
        t_turn += TRIAL_TURN_S + TRIAL_STRAIGHT_S
    return {"amplitude": amp, "pace": pace, "heading": heading, "stand_s": stand, "walk_s": walk0,
            "brisk_s": brisk + 2.0, "turns_s": turns}


TRIAL_STAND_S = 3.0  # standing still before setting off
TRIAL_STRAIGHT_S = 8.0  # walking straight between turns (about 10 m, a lab's walkway)
TRIAL_TURN_S = 2.0


def _walk_trial(T: int, fps: float, body: Body, speed: float, rng: np.random.Generator) -> Motion:
    p = walk_trial_profile(np.arange(T) / fps)
    return _gait(T, fps, body, speed, rng, run=False, amplitude=p["amplitude"], pace=p["pace"],
                 heading=p["heading"])


def _squat(T: int, fps: float, body: Body, tempo: float, rng: np.random.Generator) -> Motion:
    t = np.arange(T) / fps
    leg = _leg_geometry(body)
    period = 3.0 / tempo
    depth_max = 0.42 * (leg.l1 + leg.l2) * rng.uniform(0.9, 1.05)
    d = 0.5 - 0.5 * np.cos(2 * np.pi * np.clip(t - 0.5, 0, None) / period)
    pelvis_pitch = 0.55 * d
    pelvis = ry(pelvis_pitch)
    hip_z = leg.ankle_h + (leg.l1 + leg.l2) * 0.995 - depth_max * d
    hip_x = -0.35 * depth_max * d  # hips go back, knees forward
    hip = np.stack([hip_x, hip_z], -1)
    ankle = np.stack([np.zeros(T), np.full(T, leg.ankle_h)], -1)
    th, sh = _ik(hip, ankle, leg)
    pose = _Pose.identity(T)
    pose.set("pelvis", pelvis)
    _legs_from_ik(pose, pelvis, {"l": th, "r": th}, {"l": sh, "r": sh}, {"l": 0 * t, "r": 0 * t})
    _trunk(pose, 0.15 * d - 0.1 * d)
    arm = 1.45 * d
    _arms(pose, arm, arm, 0.1 + 0 * t, 0.1 + 0 * t, down_l=1.36 - 0.1 * d, down_r=1.36 - 0.1 * d)
    return _planted(pose, body, hip, {"l": ankle, "r": ankle}, fps)


def _planted(pose: _Pose, body: Body, hip_xz: np.ndarray, ankles: dict, fps: float) -> Motion:
    """Root from the IK hip trajectory: place the pelvis so the hip joints are where the IK
    put them (hip x/z are given relative to the planted feet)."""
    R = pose.globals()
    T = R.shape[0]
    j = forward_kinematics(R, np.zeros(3), body.offsets)
    hip_rel = 0.5 * (j[:, I["l_thigh"]] + j[:, I["r_thigh"]])
    root = np.zeros((T, 3))
    root[:, 0] = hip_xz[:, 0] - hip_rel[:, 0]
    root[:, 2] = hip_xz[:, 1] - hip_rel[:, 2]
    return Motion(rot=R, root=root, fps=fps, body=body)


def _lunge(T: int, fps: float, body: Body, tempo: float, rng: np.random.Generator) -> Motion:
    """Forward lunges, alternating legs: step out, lower, rise, step back."""
    t = np.arange(T) / fps
    leg = _leg_geometry(body)
    L = leg.l1 + leg.l2
    step = 0.75 * L * rng.uniform(0.93, 1.07)
    durs = np.array([0.3, 0.7, 0.8, 0.8, 0.7]) / tempo  # stand, step out, down, up, step back
    cyc = durs.sum()
    edges = np.concatenate([[0], np.cumsum(durs)])
    k = np.floor(t / cyc).astype(int)
    u = t - k * cyc
    out = _smoothstep((u - edges[1]) / durs[1]) - _smoothstep((u - edges[4]) / durs[4])
    down = _smoothstep((u - edges[2]) / durs[2]) - _smoothstep((u - edges[3]) / durs[3])
    lift = sum(np.sin(np.pi * np.clip((u - edges[i]) / durs[i], 0, 1)) for i in (1, 4))
    front_is_left = (k % 2) == 0
    fx = step * out  # front foot x
    fz = leg.ankle_h + 0.08 * L * lift
    # back foot: heel rises as the body lowers, toe stays
    pitch_b = 0.75 * down * out
    bx, bz = _ankle_for_heel_raise(np.full(T, leg.toe_fwd), pitch_b, leg)
    hip_x = 0.45 * fx
    drop = 0.36 * L * down
    hip_z = leg.ankle_h + 0.995 * L - drop - 0.03 * L * out
    hip = np.stack([hip_x, hip_z], -1)
    front = np.stack([fx, fz], -1)
    back = np.stack([bx, bz], -1)
    th_f, sh_f = _ik(hip, front, leg)
    th_b, sh_b = _ik(hip, back, leg)
    pose = _Pose.identity(T)
    pose.set("pelvis", np.broadcast_to(np.eye(3), (T, 3, 3)))
    fl = front_is_left
    thigh = {"l": np.where(fl, th_f, th_b), "r": np.where(fl, th_b, th_f)}
    shank = {"l": np.where(fl, sh_f, sh_b), "r": np.where(fl, sh_b, sh_f)}
    pitch = {"l": np.where(fl, 0.0, pitch_b), "r": np.where(fl, pitch_b, 0.0)}
    _legs_from_ik(pose, np.broadcast_to(np.eye(3), (T, 3, 3)), thigh, shank, pitch)
    _trunk(pose, 0.05 * down)
    _arms(pose, 0.1 * down, 0.1 * down, 0.3 + 0 * t, 0.3 + 0 * t)
    # a fixed lateral offset between the feet is the hip width: IK is planar per leg
    return _planted(pose, body, hip, {}, fps)


def _jump(T: int, fps: float, body: Body, tempo: float, rng: np.random.Generator) -> Motion:
    """Countermovement jumps in place: stand, crouch, push off onto the toes, fly a
    ballistic parabola, land, absorb, stand."""
    t = np.arange(T) / fps
    leg = _leg_geometry(body)
    L = leg.l1 + leg.l2
    h_jump = 0.22 * rng.uniform(0.85, 1.15)
    v0 = np.sqrt(2 * G * h_jump)
    t_fl = 2 * v0 / G
    crouch = 0.28 * L
    stand_z = leg.ankle_h + 0.995 * L
    pmax = 0.9  # foot pitch at take-off (on the toes)
    _, ank_to_z = _ankle_for_heel_raise(np.zeros(1), np.array([pmax]), leg)
    to_z = float(ank_to_z[0]) + 0.995 * L  # hip height at take-off
    durs = np.array([0.6, 0.5, 0.25, t_fl * tempo, 0.3, 0.6]) / tempo  # stand, down, push, flight, land, up
    cyc = durs.sum()
    e = np.concatenate([[0], np.cumsum(durs)])
    u = t % cyc
    hip_z = np.full(T, stand_z)
    pitch = np.zeros(T)
    s1 = (u >= e[1]) & (u < e[2])
    hip_z[s1] = stand_z - crouch * _smoothstep((u[s1] - e[1]) / durs[1])
    s2 = (u >= e[2]) & (u < e[3])
    x = (u[s2] - e[2]) / durs[2]
    # cubic Hermite from (low, v=0) to (take-off height, v0)
    h00, h01, h11 = 2 * x**3 - 3 * x**2 + 1, -2 * x**3 + 3 * x**2, x**3 - x**2
    z_low = stand_z - crouch
    hip_z[s2] = h00 * z_low + h01 * to_z + h11 * v0 * durs[2]
    pitch[s2] = pmax * _smoothstep((x - 0.4) / 0.6)
    s3 = (u >= e[3]) & (u < e[4])
    tau = u[s3] - e[3]
    hip_z[s3] = to_z + v0 * tau - 0.5 * G * tau**2
    pitch[s3] = pmax
    s4 = (u >= e[4]) & (u < e[5])
    x = (u[s4] - e[4]) / durs[4]
    land_low = stand_z - 0.6 * crouch
    # Hermite from (take-off height, -v0) to (land_low, 0)
    hip_z[s4] = (2 * x**3 - 3 * x**2 + 1) * to_z + (-2 * x**3 + 3 * x**2) * land_low + (x**3 - 2 * x**2 + x) * (
        -v0 * durs[4])
    pitch[s4] = pmax * (1 - _smoothstep(x / 0.5))
    s5 = u >= e[5]
    hip_z[s5] = land_low + (stand_z - land_low) * _smoothstep((u[s5] - e[5]) / durs[5])
    flying = s3
    ax, az = _ankle_for_heel_raise(np.full(T, leg.toe_fwd), pitch, leg)
    az = np.where(flying, hip_z - (to_z - az), az)
    hip_x = -0.2 * np.clip(stand_z - hip_z, 0.0, None)
    hip = np.stack([hip_x, hip_z], -1)
    ankle = np.stack([ax, az], -1)
    th, sh = _ik(hip, ankle, leg)
    lean = 0.9 * (stand_z - hip_z) / crouch
    pelvis = ry(0.5 * np.clip(lean, 0, None))
    pose = _Pose.identity(T)
    pose.set("pelvis", pelvis)
    _legs_from_ik(pose, pelvis, {"l": th, "r": th}, {"l": sh, "r": sh}, {"l": pitch, "r": pitch})
    _trunk(pose, 0.2 * np.clip(lean, 0, None))
    # arms back in the crouch, forward-up through the push and flight
    swing = np.interp(u, [0, e[1], e[2], e[3], e[4], e[5], cyc], [0, 0, -0.7, 2.2, 0.8, 0.2, 0])
    _arms(pose, swing, swing, 0.2 + 0 * t, 0.2 + 0 * t)
    return _planted(pose, body, hip, {}, fps)


def _arm_raises(T: int, fps: float, body: Body, tempo: float, rng: np.random.Generator) -> Motion:
    """Lateral raises (to overhead), then front raises, alternating, standing."""
    t = np.arange(T) / fps
    period = 3.0 / tempo
    k = np.floor(t / period).astype(int)
    u = (t % period) / period
    r = 0.5 - 0.5 * np.cos(2 * np.pi * u)
    lateral = (k % 2) == 0
    amp = rng.uniform(0.95, 1.05)
    down = np.where(lateral, 1.36 - 2.9 * amp * r, 1.36)
    swing = np.where(lateral, 0.0, 2.9 * amp * r)
    pose = _Pose.identity(T)
    _trunk(pose, -0.04 * r)
    _arms(pose, swing, swing, 0.15 + 0 * t, 0.15 + 0 * t, down_l=down, down_r=down)
    R, root = _stand_base(T, body, pose)
    return Motion(rot=R, root=root, fps=fps, body=body)


def _stand(T: int, fps: float, body: Body, tempo: float, rng: np.random.Generator) -> Motion:
    """Quiet standing: arms hanging, slow postural sway (~1 cm) and breathing."""
    t = np.arange(T) / fps
    f1, f2, ph = rng.uniform(0.15, 0.3), rng.uniform(0.2, 0.35), rng.uniform(0, 2 * np.pi, 2)
    sway_x = 0.012 * np.sin(2 * np.pi * f1 * t + ph[0])
    sway_y = 0.008 * np.sin(2 * np.pi * f2 * t + ph[1])
    pose = _Pose.identity(T)
    leg = _leg_geometry(body)
    lean_ankle = np.arctan2(sway_x, leg.l1 + leg.l2)
    roll = np.arctan2(sway_y, leg.l1 + leg.l2)
    # inverted pendulum about the ankles: whole body leans, feet stay flat
    body_tilt = ry(lean_ankle) @ rx(-roll)
    pose.set("pelvis", body_tilt)
    for s in ("l", "r"):
        pose.set(f"{s}_foot", np.swapaxes(body_tilt, -1, -2))
    _trunk(pose, 0.01 * np.sin(2 * np.pi * 0.25 * t))
    _arms(pose, 0.05 + 0 * t, 0.05 + 0 * t, 0.15 + 0 * t, 0.15 + 0 * t, down_l=1.4, down_r=1.4)
    R = pose.globals()
    j = forward_kinematics(R, np.zeros(3), body.offsets)
    cp = contact_points(R, j, body)
    root = np.zeros((T, 3))
    # keep the feet where they are: cancel the heel points' horizontal motion
    root[:, :2] = -(cp[:, [0, 2], :2].mean(1) - cp[0, [0, 2], :2].mean(0))
    root[:, 2] = -cp[..., 2].min(-1)
    return Motion(rot=R, root=root, fps=fps, body=body)


def _hold(T: int, fps: float, body: Body, npose: bool) -> Motion:
    pose = _Pose.identity(T)
    if npose:
        _arms(pose, 0 * np.zeros(T), np.zeros(T), np.zeros(T), np.zeros(T), down_l=np.full(T, np.deg2rad(80)),
              down_r=np.full(T, np.deg2rad(80)))
    R, root = _stand_base(T, body, pose)
    return Motion(rot=R, root=root, fps=fps, body=body)


def leg_cycle(side: str = "l", cycles: int = 5, stand_s: float = 1.5, period_s: float = 1.6, height: float = 1.75,
              fps: float = 60.0, seed: int = 0) -> Motion:
    """A functional-calibration trial: the N-pose held, then one leg swung forward and back
    ``cycles`` times with the knee bending (hip -15..35 deg, knee 0..70 deg, amplitudes +-8 %
    by ``seed``), then the N-pose again. The leg's segments turn about the hip's and knee's
    lateral axes, which is what the trial is recorded for: each sensor's flexion axis."""
    if side not in ("l", "r"):
        raise ValueError(f"side must be 'l' or 'r', not {side!r}")
    rng = np.random.default_rng(seed)
    body = Body.from_height(height)
    n_stand, n_swing = int(round(stand_s * fps)), int(round(cycles * period_s * fps))
    T = 2 * n_stand + n_swing
    t = (np.arange(T) - n_stand) / fps
    on = (t >= 0) & (t < cycles * period_s)
    ph = 2 * np.pi * t / period_s
    k = rng.uniform(0.92, 1.08, 2)
    hip = np.where(on, np.deg2rad(25.0) * k[0] * np.sin(ph) + np.deg2rad(10.0) * (1 - np.cos(ph)) / 2, 0.0)
    knee = np.where(on, np.deg2rad(70.0) * k[1] * (1 - np.cos(ph)) / 2, 0.0)
    pose = _Pose.identity(T)
    _arms(pose, np.zeros(T), np.zeros(T), np.zeros(T), np.zeros(T), down_l=np.full(T, np.deg2rad(80)),
          down_r=np.full(T, np.deg2rad(80)))
    pose.set(f"{side}_thigh", ry(-hip))
    pose.set(f"{side}_shank", ry(knee))
    R = pose.globals()
    cp = contact_points(R, forward_kinematics(R, np.zeros(3), body.offsets), body)
    stance = [2, 3] if side == "l" else [0, 1]  # the standing foot stays on the floor, the swinging one is free
    root = np.zeros((T, 3))
    root[:, 2] = -cp[:, stance, 2].min(-1)
    return Motion(rot=R, root=root, fps=fps, body=body, name=f"leg_cycle_{side}", source="sim_devices.motions",
                  meta={"kind": "leg_cycle", "side": side, "seed": seed, "height": height})


# --------------------------------------------------------------------------- public API
def generate(
    kind: str,
    height: float = 1.75,
    speed: float | None = None,
    seconds: float = 6.0,
    seed: int = 0,
    fps: float = 60.0,
    heading_deg: float = 0.0,
) -> Motion:
    """A procedural motion of `kind` (see KINDS) on a body of `height` m, floor-aligned,
    facing +X turned by `heading_deg` about Z (module docstring for `speed`)."""
    if kind not in KINDS:
        raise ValueError(f"unknown motion kind {kind!r}; known: {', '.join(KINDS)}")
    if not seconds > 0:
        raise ValueError("seconds must be positive")
    body = Body.from_height(height)
    rng = np.random.default_rng(seed)
    T = max(int(round(seconds * fps)) + 1, 2)
    sp = DEFAULT_SPEED.get(kind, 1.0) if speed is None else float(speed)
    if not sp > 0:
        raise ValueError("speed must be positive")
    if kind in ("walk", "jog"):
        m = _gait(T, fps, body, sp, rng, run=(kind == "jog"))
    elif kind == "walk_trial":
        m = _walk_trial(T, fps, body, sp, rng)
    elif kind == "squat":
        m = _squat(T, fps, body, sp, rng)
    elif kind == "lunge":
        m = _lunge(T, fps, body, sp, rng)
    elif kind == "jump":
        m = _jump(T, fps, body, sp, rng)
    elif kind == "arm_raises":
        m = _arm_raises(T, fps, body, sp, rng)
    elif kind == "stand":
        m = _stand(T, fps, body, sp, rng)
    else:
        m = _hold(T, fps, body, npose=(kind == "npose"))
    rot, root = m.rot, m.root
    if heading_deg:
        Rh = rz(np.deg2rad(heading_deg))
        rot = Rh @ rot
        root = root @ Rh.T
    m = Motion(rot=rot, root=root, fps=fps, body=body, name=f"{kind}", source="sim_devices.motions",
               meta={"kind": kind, "speed": sp, "seed": seed, "height": height})
    return m.floor_aligned()


def write_amass_npz(motion: Motion, path: str | Path, gender: str = "neutral") -> Path:
    """Write `motion` as an AMASS/SMPL-H .npz: ``poses`` (T, 156) axis-angle local
    rotations in SMPL convention (inference.amass_frames), ``trans`` (T, 3) the pelvis
    joint path (Z-up world), ``mocap_framerate``, ``betas`` (16,) zeros, ``gender``, plus
    ``imucap_height_m`` so the loader rebuilds the same body."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = motion.meta or {}
    np.savez(
        path, poses=global_to_amass_poses(motion.rot), trans=motion.root.astype(np.float64),
        mocap_framerate=np.array(float(motion.fps)), betas=np.zeros(16), gender=np.array(gender),
        imucap_height_m=np.array(float(motion.body.height)),
        imucap_kind=np.array(str(meta.get("kind", motion.name))), imucap_seed=np.array(int(meta.get("seed", 0))),
    )
    return path


def generate_file(path: str | Path, kind: str, **kw) -> Path:
    """generate() then write_amass_npz(); returns the path."""
    return write_amass_npz(generate(kind, **kw), path)


__all__ = ["KINDS", "generate", "generate_file", "leg_cycle", "walk_trial_profile", "write_amass_npz"]
