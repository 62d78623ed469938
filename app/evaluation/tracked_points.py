"""Tracked points (a VR headset and controllers) in an evaluation, read the way the live
chain reads them: `imucap evaluate --points head,l_hand,r_hand`.

Why here: the live path takes a tracked device's poses through ``drivers.vmc`` (each pose
carries the IMU reading it implies, ``drivers/vmc/implied_imu.py``) to the model site it
stands for (``MODEL_SITES``: a controller stands for the wrist sensor). An evaluation that
claims to measure that path has to go through the same code, which sits in ``drivers``
and ``sim_devices``; the evaluation harness (``inference.evaluation.runner``) may import
neither, so it takes the signals of these sites from a callable this module builds.

Per clip (already turned to face +X, as the harness does) and per point:
1. the device's pose over the clip (``sim_devices.devices.vr_rig.tracked_points``: the
   headset between the eyes, a controller's grip in the fist), sent at ``rate`` Hz (72,
   as the simulated rig) with the rig's tracking error and latency (``SimVrRig.poses``:
   1 mm jitter + 2 mm wander per axis, 0.3 deg, 15 ms);
2. the implied free acceleration (``ImpliedImu``, the driver's own estimator);
3. onto the 60 Hz grid by linear interpolation (positions' accelerations) and normalised
   linear interpolation of quaternions, as the hub's interpolation does;
4. the device's orientation turned into the model site's bone with the rotation that
   matches them on the clip's first frame: a calibration in the standing start, as the
   evaluation's IMU signals are calibrated. A controller held in the hand then reads the
   hand's turn for the forearm's: the wrist's own motion is an error this input carries
   (a model trained on tracked points would not have it).

Positions enter only through the acceleration for now: the model has no position input
yet (NOTES.md, "VR input and the three-point task").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from drivers.vmc.device import MODEL_SITES
from drivers.vmc.implied_imu import ImpliedImu
from inference.body.motion import Motion
from inference.body.rotations import matrix_to_quat, quat_continuous, quat_multiply, quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX, SEGMENTS, SITE_SEGMENT
from inference.body.tracked import POINT_SEGMENTS, TRACKED_POINTS, point_features, presence
from inference.signals.synthesis import FPS_SIGNAL
from sim_devices.devices.vr_rig import ROLES, SimVrRig, TrackedSource, TrackingNoise

POINTS: tuple[str, ...] = tuple(ROLES)  # head, l_hand, r_hand, pelvis
RIG_RATE = 72.0  # Hz: the simulated rig's, a common headset refresh

TrackedSignals = Callable[[Motion, int], dict[str, tuple[np.ndarray, np.ndarray]]]


def parse_points(text: str | Sequence[str]) -> list[str]:
    """``head,l_hand,r_hand`` -> the list, unknown names refused in one line."""
    items = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    items = [s for s in items if s]
    unknown = [s for s in items if s not in POINTS]
    if unknown:
        raise ValueError(f"--points: unknown tracked point(s) {', '.join(unknown)} (known: {', '.join(POINTS)})")
    if len(set(items)) != len(items):
        raise ValueError(f"--points: a point named twice in {','.join(items)}")
    return items


def model_sites(points: Sequence[str]) -> list[str]:
    """The model sites the points stand for (``drivers.vmc.MODEL_SITES``)."""
    return [MODEL_SITES[p] for p in points]


def check_sites(sensors: Sequence[str], points: Sequence[str]) -> None:
    """A site is an IMU or a tracked point, not both."""
    both = sorted(set(sensors) & set(model_sites(points)))
    if both:
        who = ", ".join(f"{s} (point {p})" for p in points for s in both if MODEL_SITES[p] == s)
        raise ValueError(f"--sensors and --points both give {who}: name each site once")


def _nlerp(q: np.ndarray, t_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Quaternions (N, 4) at times ``t_src`` onto ``t``: normalised linear interpolation
    on a sign-continuous sequence (the hub's interpolation does the same)."""
    q = quat_continuous(q)
    out = np.stack([np.interp(t, t_src, q[:, k]) for k in range(4)], axis=-1)
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def rig_poses(motion: Motion, points: Sequence[str], seed: int, noise: TrackingNoise,
               rate: float) -> tuple[Motion, np.ndarray, np.ndarray, dict[str, tuple[list, list]]]:
    """The rig's noisy poses of ``points`` over ``motion``: (the 60 Hz motion, its grid, the
    rig's send times, point -> (positions, quaternions) per send)."""
    m60 = motion.resample(FPS_SIGNAL)
    grid = np.arange(m60.n_frames) / FPS_SIGNAL
    rig = SimVrRig(TrackedSource(m60, tuple(points)), rate=rate, noise=noise)
    rig.rng = np.random.default_rng(seed)
    t_rig = np.arange(int(np.floor(grid[-1] * rate)) + 1) / rate
    poses: dict[str, tuple[list, list]] = {p: ([], []) for p in points}
    site_of_serial = {rig.serials[p]: p for p in points}
    for t in t_rig:
        for pose in rig.poses(float(t)):
            pos, quat = poses[site_of_serial[pose.serial]]
            pos.append(np.asarray(pose.position, float))
            quat.append(np.asarray(pose.quat, float))
    return m60, grid, t_rig, poses


def _onto_segment(q_dev: np.ndarray, R_seg0: np.ndarray) -> np.ndarray:
    """Device orientations (T, 4) turned into their segment's, matched on the first frame
    (a calibration in the standing start)."""
    q_db = matrix_to_quat(quat_to_matrix(q_dev[0]).T @ R_seg0)
    q = quat_multiply(q_dev, np.broadcast_to(q_db, q_dev.shape))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def tracked_points_input(points: Sequence[str], noise: TrackingNoise | None = None, rate: float = RIG_RATE):
    """For a model that reads tracked points (``ModelConfig.points``): a callable (motion,
    seed) -> (segment name -> quaternion (T, 4) of the segment the point sits on, the
    position input (T, 16)) on the motion's 60 Hz frames, for
    ``inference.evaluation.runner.clip_input(tracked=...)``: the rig's noisy poses as
    ``tracked_signals`` takes them, each point's orientation for its own segment (a
    controller for the hand) and its position for ``inference.body.tracked.point_features``."""
    points = parse_points(points)
    if "head" not in points:
        raise ValueError("--points for a model with a position input needs the headset (head): "
                         "the positions are read against it")
    noise = noise or TrackingNoise()
    flags = presence(points)

    def signals(motion: Motion, seed: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        m60, grid, t_rig, poses = rig_poses(motion, points, seed, noise, rate)
        pos = np.zeros((len(grid), len(TRACKED_POINTS), 3))
        segs: dict[str, np.ndarray] = {}
        for k, name in enumerate(TRACKED_POINTS):
            if name not in poses:
                continue
            P, Q = (np.stack(v) for v in poses[name])
            pos[:, k] = np.stack([np.interp(grid, t_rig, P[:, a]) for a in range(3)], axis=-1)
            seg = POINT_SEGMENTS[k]
            segs[SEGMENTS[seg]] = _onto_segment(_nlerp(Q, t_rig, grid), m60.rot[0, seg])
        return segs, point_features(pos, flags)

    return signals


def tracked_signals(points: Sequence[str], noise: TrackingNoise | None = None, rate: float = RIG_RATE,
                    ) -> TrackedSignals:
    """A callable (motion, seed) -> model site -> (quat (T, 4) w x y z bone -> world, free
    acceleration (T, 3) world, unsmoothed) on the motion's 60 Hz frames, for
    ``inference.evaluation.runner.clip_input(tracked=...)``. ``noise``: the rig's tracking
    error (default ``TrackingNoise()``; ``NO_NOISE`` for none)."""
    points = parse_points(points)
    noise = noise or TrackingNoise()

    def signals(motion: Motion, seed: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        m60, grid, t_rig, poses = rig_poses(motion, points, seed, noise, rate)
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for p in points:
            P, Q = (np.stack(v) for v in poses[p])
            est = ImpliedImu()
            acc_t, acc_v = [], []
            for t, pos, q in zip(t_rig, P, Q):
                reading = est.update(float(t), pos, q)
                if reading is not None:
                    acc_t.append(float(t))
                    acc_v.append(reading.free_acc)
            if acc_t:
                a = np.stack(acc_v)
                free = np.stack([np.interp(grid, np.asarray(acc_t), a[:, k]) for k in range(3)], axis=-1)
            else:
                free = np.zeros((len(grid), 3))
            site = MODEL_SITES[p]
            out[site] = (_onto_segment(_nlerp(Q, t_rig, grid), m60.rot[0, SEGMENT_INDEX[SITE_SEGMENT[site]]]), free)
        return out

    return signals
