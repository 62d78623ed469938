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
from inference.body.rotations import matrix_to_quat, quat_multiply, quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX, SITE_SEGMENT
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
    q = q.copy()
    d = np.sum(q[1:] * q[:-1], axis=-1)
    q[1:] *= np.cumprod(np.where(d < 0, -1.0, 1.0))[:, None]
    out = np.stack([np.interp(t, t_src, q[:, k]) for k in range(4)], axis=-1)
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def tracked_signals(points: Sequence[str], noise: TrackingNoise | None = None, rate: float = RIG_RATE,
                    ) -> TrackedSignals:
    """A callable (motion, seed) -> model site -> (quat (T, 4) w x y z bone -> world, free
    acceleration (T, 3) world, unsmoothed) on the motion's 60 Hz frames, for
    ``inference.evaluation.runner.clip_input(tracked=...)``. ``noise``: the rig's tracking
    error (default ``TrackingNoise()``; ``NO_NOISE`` for none)."""
    points = parse_points(points)
    noise = noise or TrackingNoise()

    def signals(motion: Motion, seed: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        m60 = motion.resample(FPS_SIGNAL)
        T = m60.n_frames
        grid = np.arange(T) / FPS_SIGNAL
        rig = SimVrRig(TrackedSource(m60, tuple(points)), rate=rate, noise=noise)
        rig.rng = np.random.default_rng(seed)
        n = int(np.floor(grid[-1] * rate)) + 1
        t_rig = np.arange(n) / rate
        est = {p: ImpliedImu() for p in points}
        pos_q: dict[str, list[np.ndarray]] = {p: [] for p in points}
        acc_t: dict[str, list[float]] = {p: [] for p in points}
        acc_v: dict[str, list[np.ndarray]] = {p: [] for p in points}
        site_of_serial = {rig.serials[p]: p for p in points}
        for t in t_rig:
            for pose in rig.poses(float(t)):
                p = site_of_serial[pose.serial]
                q = np.asarray(pose.quat, float)
                pos_q[p].append(q)
                reading = est[p].update(float(t), np.asarray(pose.position, float), q)
                if reading is not None:
                    acc_t[p].append(float(t))
                    acc_v[p].append(reading.free_acc)
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for p in points:
            site = MODEL_SITES[p]
            q_dev = _nlerp(np.stack(pos_q[p]), t_rig, grid)
            if acc_t[p]:
                a = np.stack(acc_v[p])
                free = np.stack([np.interp(grid, np.asarray(acc_t[p]), a[:, k]) for k in range(3)], axis=-1)
            else:
                free = np.zeros((T, 3))
            # device -> bone, matched on the first frame (a calibration in the standing start)
            R_bone0 = m60.rot[0, SEGMENT_INDEX[SITE_SEGMENT[site]]]
            R_dev0 = quat_to_matrix(q_dev[0])
            q_db = matrix_to_quat(R_dev0.T @ R_bone0)
            quat = quat_multiply(q_dev, np.broadcast_to(q_db, q_dev.shape))
            out[site] = (quat / np.linalg.norm(quat, axis=-1, keepdims=True), free)
        return out

    return signals
