"""What a sensor suit would measure on a given motion: the synthesized signals that train
the model and that the simulated devices replay.

From a `Motion` resampled to 60 Hz (the rate of the paper's Xsens stream):
- orientation: the carrying segment's global orientation (paper sec. 3.3: IMU
  orientation = segment orientation);
- free acceleration (world frame, gravity removed): double finite difference of the site
  position, then the centred 11-frame moving average (the same routine the live
  resampler uses, so training and deployment see the same filter). A motion captured
  below 60 Hz (Bandai: 30) has its site paths put on the 60 Hz grid by a cubic spline
  (``upsampled_site_paths``): on the slerped, piecewise-linear path the double difference
  alternates between twice the acceleration and zero, a 30 Hz component as large as the
  signal that no real sensor shows (docs/real_signals.md);
- specific force (sensor frame, gravity included, unsmoothed): what a raw accelerometer
  reads, R^T (a - g) with g = (0, 0, -9.81): +9.81 along world up when still, 0 in free fall;
- angular velocity in the sensor frame from consecutive orientations (centred difference
  on SO(3), second order accurate);
- heel/toe contacts: contact point speed below 0.3 m/s (paper's label);
- per-foot insole force: body weight plus vertical inertial force of the centre of mass,
  m (g + a_com_z), shared between the feet by their number of contact points; 0 in flight.

Noise (`NoiseModel`) is applied the way a device produces it: white noise and bias on the
raw accelerometer and gyro, an orientation error (white plus heading random walk), a
random sensor-to-segment mounting rotation, and a per-sensor heading offset of the
sensor's own reference frame. The free acceleration is then recomputed the way a device
does (reported orientation x measured specific force + g), so orientation errors leak
gravity into it exactly as they would. The drawn mounting and heading rotations are stored
in ``SiteSignals.meta`` because calibration must later remove them (tests compare).

Segment masses: de Leva, P. (1996), "Adjustments to Zatsiorsky-Seluyanov's segment inertia
parameters", J. Biomechanics 29(9):1223-1230, Table 4 (male mass fractions: head+neck 6.94%,
trunk 43.46% = upper 15.96 + middle 16.33 + lower 11.17, upper arm 2.71, forearm 1.62,
hand 0.61, thigh 14.16, shank 4.33, foot 1.37). The split of a table segment over several
of our segments (trunk over pelvis/spine1-3/collars, head+neck, hand/fingers, foot/toes)
is ours. Segment COM at the midpoint of its joint and its main child's joint (paper's
energy metric).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.body.body import MAIN_CHILD, Body, points_on_segments
from inference.body.conventions import rot_z
from inference.body.motion import Motion
from inference.body.rotations import matrix_about_axis, matrix_to_quat, so3_exp, so3_log
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX, SEGMENTS, SITE_SEGMENT_INDEX, SITES
from inference.signals.resample import FPS_SIGNAL, moving_average
from inference.signals.site_signals import SiteSignals

GRAVITY = np.array([0.0, 0.0, -9.81])
G = 9.81
CONTACT_SPEED = 0.3  # m/s, paper's contact label threshold
DEFAULT_BMI = 22.0
_CHUNK = 4096  # frames per synthesis chunk
_MARGIN = 4  # overlap on each side (>= the 1-frame stencil of the finite differences)

# de Leva (1996) mass fractions distributed over our 24 segments (module docstring)
_MASS_PERCENT: dict[str, float] = {
    "pelvis": 11.17, "spine1": 8.17, "spine2": 8.16, "spine3": 11.96, "l_collar": 2.0, "r_collar": 2.0,
    "neck": 1.5, "head": 5.44,
    "l_upperarm": 2.71, "r_upperarm": 2.71, "l_forearm": 1.62, "r_forearm": 1.62,
    "l_hand": 0.37, "r_hand": 0.37, "l_fingers": 0.24, "r_fingers": 0.24,
    "l_thigh": 14.16, "r_thigh": 14.16, "l_shank": 4.33, "r_shank": 4.33,
    "l_foot": 1.10, "r_foot": 1.10, "l_toes": 0.27, "r_toes": 0.27,
}
SEGMENT_MASS_FRACTION = np.array([_MASS_PERCENT[n] for n in SEGMENTS]) / 100.0
assert abs(SEGMENT_MASS_FRACTION.sum() - 1.0) < 1e-9

# COM of segments without a main child (leaf segments), as a fraction of height, in the
# segment's rest frame
_LEAF_COM: dict[str, tuple[float, float, float]] = {
    "head": (0.01, 0.0, 0.065), "l_toes": (0.025, 0.0, 0.0), "r_toes": (0.025, 0.0, 0.0),
    "l_fingers": (0.0, 0.03, 0.0), "r_fingers": (0.0, -0.03, 0.0),
}


def body_mass(height: float, bmi: float = DEFAULT_BMI) -> float:
    """Body mass (kg) from height by a BMI (default 22, mid normal range) when none is given."""
    return float(bmi * height * height)


def segment_com(rot: np.ndarray, joints: np.ndarray, body: Body) -> np.ndarray:
    """(T, 24, 3) segment centres of mass: midpoint of the segment's joint and its main
    child's joint; leaf segments (head, toes, fingers) a fixed point on the segment."""
    com = joints.copy()
    segs = np.array(sorted(MAIN_CHILD))
    kids = np.array([MAIN_CHILD[s] for s in segs])
    com[:, segs] = 0.5 * (joints[:, segs] + joints[:, kids])
    leaf = [SEGMENT_INDEX[n] for n in _LEAF_COM]
    local = np.array(list(_LEAF_COM.values())) * body.height
    com[:, leaf] = points_on_segments(rot, joints, leaf, local)
    return com


def kinetic_energy(motion: Motion, mass: float | None = None) -> np.ndarray:
    """(T,) total linear kinetic energy sum_i 0.5 m_i |v_com_i|^2 (J), velocities by central
    differences: the paper's clip sampling metric."""
    m = body_mass(motion.body.height) if mass is None else mass
    com = segment_com(motion.rot, motion.joints(), motion.body)
    v = np.gradient(com, 1.0 / motion.fps, axis=0)
    return 0.5 * m * np.einsum("s,tsk,tsk->t", SEGMENT_MASS_FRACTION, v, v)


def second_difference(p: np.ndarray, fps: float) -> np.ndarray:
    """Acceleration (T, ...) by the double finite difference (p[t+1] - 2p[t] + p[t-1]) fps^2;
    the first/last frame repeat their neighbour (the moving average then treats the clip
    ends like the live resampler's edge padding)."""
    p = np.asarray(p, dtype=np.float64)
    a = np.zeros_like(p)
    if p.shape[0] >= 3:
        a[1:-1] = (p[2:] - 2.0 * p[1:-1] + p[:-2]) * (fps * fps)
        a[0] = a[1]
        a[-1] = a[-2]
    return a


def angular_velocity(R: np.ndarray, fps: float) -> np.ndarray:
    """Body-frame angular velocity (T, ..., 3) from orientations R_WB (T, ..., 3, 3):
    log(R[t-1]^T R[t+1]) fps / 2 inside, one-sided at the ends."""
    T = R.shape[0]
    w = np.zeros(R.shape[:-1])
    if T < 2:
        return w
    Rt = np.swapaxes(R, -1, -2)
    if T >= 3:
        w[1:-1] = so3_log(Rt[:-2] @ R[2:]) * (fps / 2.0)
    w[0] = so3_log(Rt[0] @ R[1]) * fps
    w[-1] = so3_log(Rt[-2] @ R[-1]) * fps
    return w


def contact_labels(points: np.ndarray, fps: float, threshold: float = CONTACT_SPEED) -> np.ndarray:
    """(T, 4) bool: heel/toe point speed (central differences) below `threshold` m/s."""
    if points.shape[0] < 2:
        return np.ones(points.shape[:2], dtype=bool)
    v = np.gradient(points, 1.0 / fps, axis=0)
    return np.linalg.norm(v, axis=-1) < threshold


def upsampled_site_paths(motion: Motion, fps: float) -> np.ndarray | None:
    """(T, 13, 3) site positions on the ``fps`` grid of ``motion.resample(fps)`` by a cubic
    spline through the captured frames, when the motion is captured below ``fps``; None
    otherwise (a resampling down or at the same rate is already smooth enough). Only the
    accelerations are taken from these paths: the orientations stay slerped."""
    if motion.fps >= fps - 1e-9 or motion.n_frames < 4:
        return None
    from scipy.interpolate import CubicSpline

    n_new = int(np.floor(motion.duration * fps + 1e-9)) + 1
    t_new = np.minimum(np.arange(n_new) / fps, motion.times[-1])
    return CubicSpline(motion.times, motion.sites(motion.joints()), axis=0)(t_new)


@dataclass
class Kinematics:
    """Everything synthesis derives from positions, at the motion's rate (60 Hz)."""

    fps: float
    rot: np.ndarray  # (T, 24, 3, 3)
    root: np.ndarray  # (T, 3)
    joints: np.ndarray  # (T, 24, 3)
    site_pos: np.ndarray  # (T, 13, 3)
    site_acc_raw: np.ndarray  # (T, 13, 3) world, unsmoothed
    contact_pos: np.ndarray  # (T, 4, 3)
    contacts: np.ndarray  # (T, 4) bool


def kinematics(motion: Motion, fps: float = FPS_SIGNAL) -> Kinematics:
    """Resample to `fps` and compute joint, site and contact point trajectories."""
    m = motion.resample(fps)
    joints = m.joints()
    sites = m.sites(joints)
    cpts = m.contacts(joints)
    smooth = upsampled_site_paths(motion, fps)
    return Kinematics(
        fps=float(fps), rot=m.rot, root=m.root, joints=joints, site_pos=sites,
        site_acc_raw=second_difference(sites if smooth is None else smooth, fps), contact_pos=cpts,
        contacts=contact_labels(cpts, fps),
    )


def _com_z(rot: np.ndarray, joints: np.ndarray, body: Body) -> np.ndarray:
    return np.einsum("s,ts->t", SEGMENT_MASS_FRACTION, segment_com(rot, joints, body)[..., 2])


def _insole_from(com_z: np.ndarray, contacts: np.ndarray, fps: float, mass: float) -> np.ndarray:
    az = moving_average(second_difference(com_z, fps)[:, None])[:, 0]
    total = np.clip(mass * (G + az), 0.0, None)
    c = contacts.astype(np.float64)
    per_foot = np.stack([c[:, 0] + c[:, 1], c[:, 2] + c[:, 3]], axis=-1)
    n = per_foot.sum(-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(n > 0, per_foot / n, 0.0)
    return total[:, None] * share


def insole_force(kin: Kinematics, body: Body, mass: float | None = None) -> np.ndarray:
    """(T, 2) vertical force under the (left, right) foot, N: m (g + a_com_z) (COM
    acceleration smoothed like the site accelerations, never below 0), shared in
    proportion to each foot's number of contact points; 0 when no point is in contact."""
    m = body_mass(body.height) if mass is None else mass
    return _insole_from(_com_z(kin.rot, kin.joints, body), kin.contacts, kin.fps, m)


@dataclass
class NoiseModel:
    """Sensor imperfections a simulated device adds (all zero = ideal sensor).

    acc_white (m/s^2), gyro_white (rad/s), ori_white_deg: per-sample white noise std.
    acc_bias (m/s^2), gyro_bias (rad/s): std of a constant per-sensor bias.
    ori_walk_deg_per_sqrt_s: heading random walk of the sensor's orientation estimate (the
        yaw drift of magnetometer-free sensors), deg per sqrt(second).
    mounting_deg: a random sensor-to-segment rotation, random axis, angle uniform in
        [0, mounting_deg] (how a strap really sits).
    heading_deg: each sensor's reference frame is the world turned about Z by an angle
        uniform in [-heading_deg, heading_deg] (what sensor-to-world calibration removes).
    """

    acc_white: float = 0.0
    gyro_white: float = 0.0
    ori_white_deg: float = 0.0
    acc_bias: float = 0.0
    gyro_bias: float = 0.0
    ori_walk_deg_per_sqrt_s: float = 0.0
    mounting_deg: float = 0.0
    heading_deg: float = 0.0
    extra: dict = field(default_factory=dict)

    @classmethod
    def typical(cls) -> NoiseModel:
        """Roughly an Xsens MTw-class sensor strapped on by hand."""
        return cls(acc_white=0.05, gyro_white=0.01, ori_white_deg=0.3, acc_bias=0.05, gyro_bias=0.005,
                   ori_walk_deg_per_sqrt_s=0.05, mounting_deg=15.0, heading_deg=180.0)


def _random_rotations(rng: np.random.Generator, n: int, max_deg: float) -> np.ndarray:
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    ang = np.deg2rad(rng.uniform(0.0, max_deg, size=n))
    return matrix_about_axis(axis, ang)


def synthesize(
    motion: Motion,
    noise: NoiseModel | None = None,
    rng: np.random.Generator | int | None = None,
    sites: tuple[str, ...] | list[str] = SITES,
    mass: float | None = None,
    causal: bool = False,
) -> SiteSignals:
    """Signals of sensors at `sites` (default all 13) and insoles on `motion`, at 60 Hz.

    Without noise: quat is the segment orientation, free_acc the smoothed world
    acceleration, specific_force and gyro exact in the segment frame. With noise: see the
    module docstring; ``meta`` holds ``R_SB`` (S,3,3) (sensor-to-bone: R_WB = R_WG R_GS
    R_SB), ``R_WG`` (S,3,3) (sensor reference frame -> world), ``heading_rad`` (S,),
    ``acc_bias``/``gyro_bias`` (S,3), and ``free_acc_raw`` (T,S,3), the unsmoothed free
    acceleration a device would stream (the live resampler applies the moving average).
    ``causal``: ``free_acc`` smoothed with the trailing average of the low-latency mode."""
    rng = np.random.default_rng(rng)
    m60 = motion.resample(FPS_SIGNAL)
    fps = float(FPS_SIGNAL)
    T = m60.n_frames
    k_idx = [SITES.index(s) for s in sites]
    seg = [SITE_SEGMENT_INDEX[k] for k in k_idx]
    S = len(seg)
    nz = noise or NoiseModel()
    mass_kg = body_mass(motion.body.height) if mass is None else float(mass)

    # everything random is drawn up front, in a fixed order, so chunking cannot change it
    if nz.mounting_deg > 0:
        R_BS = _random_rotations(rng, S, nz.mounting_deg)
    else:
        R_BS = np.tile(np.eye(3), (S, 1, 1))
    heading = rng.uniform(-1, 1, size=S) * np.deg2rad(nz.heading_deg) if nz.heading_deg > 0 else np.zeros(S)
    acc_bias = rng.normal(size=(S, 3)) * nz.acc_bias if nz.acc_bias > 0 else np.zeros((S, 3))
    gyro_bias = rng.normal(size=(S, 3)) * nz.gyro_bias if nz.gyro_bias > 0 else np.zeros((S, 3))
    acc_w = rng.normal(size=(T, S, 3)) * nz.acc_white if nz.acc_white > 0 else None
    gyro_w = rng.normal(size=(T, S, 3)) * nz.gyro_white if nz.gyro_white > 0 else None
    walk = None
    if nz.ori_walk_deg_per_sqrt_s > 0:
        step = np.deg2rad(nz.ori_walk_deg_per_sqrt_s) / np.sqrt(fps)
        walk = np.cumsum(rng.normal(size=(T, S)), axis=0) * step
    ori_w = rng.normal(size=(T, S, 3)) * np.deg2rad(nz.ori_white_deg) if nz.ori_white_deg > 0 else None
    R_WG = rot_z(heading)
    R_GW = np.swapaxes(R_WG, -1, -2)
    R_SB = np.swapaxes(R_BS, -1, -2)
    smooth = upsampled_site_paths(motion, fps)
    acc_smooth = None if smooth is None else second_difference(smooth[:, k_idx], fps)

    quat = np.empty((T, S, 4))
    f_meas = np.empty((T, S, 3))
    g_meas = np.empty((T, S, 3))
    free_raw = np.empty((T, S, 3))
    contacts = np.empty((T, 4), dtype=bool)
    com_z = np.empty(T)
    # Time chunks with a small overlap: every quantity here needs at most +-1 neighbour,
    # so the interior of each chunk equals the whole-clip result while the working set
    # stays in cache (an hour of motion at once would need gigabytes of temporaries).
    for start in range(0, T, _CHUNK):
        stop = min(T, start + _CHUNK)
        a, b = max(0, start - _MARGIN), min(T, stop + _MARGIN)
        kin = kinematics(m60.slice(a, b), fps)
        sl = slice(start - a, stop - a)
        out = slice(start, stop)
        R_WB = kin.rot[sl][:, seg]
        a_W = kin.site_acc_raw[sl][:, k_idx] if acc_smooth is None else acc_smooth[out]
        R_WS = R_WB @ R_BS
        f = (np.swapaxes(R_WS, -1, -2) @ (a_W - GRAVITY)[..., None])[..., 0] + acc_bias
        if acc_w is not None:
            f = f + acc_w[out]
        w_B = angular_velocity(kin.rot[:, seg], fps)[sl]
        g = (R_SB @ w_B[..., None])[..., 0] + gyro_bias
        if gyro_w is not None:
            g = g + gyro_w[out]
        R_GS = R_GW @ R_WS
        if walk is not None:
            R_GS = rot_z(walk[out]) @ R_GS
        if ori_w is not None:
            R_GS = so3_exp(ori_w[out]) @ R_GS
        # as a device computes it: reported orientation x measured specific force + g
        # (exactly the world acceleration when there is no noise)
        free_raw[out] = a_W if noise is None else (R_GS @ f[..., None])[..., 0] + GRAVITY
        quat[out] = matrix_to_quat(R_GS)
        f_meas[out] = f
        g_meas[out] = g
        contacts[out] = kin.contacts[sl]
        com_z[out] = _com_z(kin.rot[sl], kin.joints[sl], motion.body)
    free = moving_average(free_raw, causal=causal)

    meta = {
        "R_SB": np.swapaxes(R_BS, -1, -2).copy(), "R_WG": R_WG, "heading_rad": heading,
        "acc_bias": acc_bias, "gyro_bias": gyro_bias, "free_acc_raw": free_raw,
        "mass_kg": mass_kg,
        "noise": nz, "name": motion.name,
    }
    return SiteSignals(
        fps=fps, sites=tuple(sites), t=np.arange(T) / fps, quat=quat, free_acc=free,
        specific_force=f_meas, gyro=g_meas, contacts=contacts,
        insole_force=_insole_from(com_z, contacts, fps, mass_kg), meta=meta,
    )


__all__ = [
    "GRAVITY", "CONTACT_SPEED", "NoiseModel", "SiteSignals", "synthesize", "kinematics", "Kinematics",
    "second_difference", "upsampled_site_paths", "angular_velocity", "contact_labels", "insole_force", "segment_com",
    "kinetic_energy", "body_mass", "SEGMENT_MASS_FRACTION", "N_SEGMENTS",
]
