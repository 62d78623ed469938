"""Session recordings for the report's tests, written by the real Recorder in seconds: the reconstruction
of each is a motion's own truth at 20 Hz (orientations, root, joints, and its heel/toe contacts as the
poser's contact values), so what the report finds can be checked against the motion itself. With
``raw=True`` the recording also holds every site's synthesized sensor signals at 60 Hz (orientation,
specific force, gyro; the typical noise model, mounting rotations included) and the calibration that
undoes the mounting, as a live session's would."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from app.live import LivePose
from app.recording import Recorder
from app.report.events import truth_contact_values
from calibration.core import Calibration
from drivers.hub.hub import HubFrame
from inference.body.motion import Motion
from inference.body.skeleton import SITE_INDEX
from inference.features.layout import N_FEATURES
from inference.poser.poser import PoseFrame
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")


def _raw(rec: Recorder, m: Motion, sites, seed: int, drop: tuple[str, ...]) -> None:
    """Every site's synthesized signals as hub frames, and the calibration that maps them to the bones;
    the sites in ``drop`` send nothing (NaN, not present)."""
    sig = synthesize(m, NoiseModel.typical(), rng=seed, sites=tuple(sites))
    S = len(sites)
    rec.on_calibration(Calibration(tuple(sites), sig.meta["R_WG"], sig.meta["R_SB"], np.zeros((S, 3)),
                                   np.ones(S, bool), residual_world_deg=np.full(S, 0.4),
                                   residual_tpose_deg=np.full(S, 0.6)), 100.0)
    present = np.array([s not in drop for s in sites])

    def sent(x: np.ndarray) -> np.ndarray:
        return np.where(present[:, None], x, np.nan)

    for i in range(len(sig.t)):
        rec.on_frame(HubFrame(t=100.0 + sig.t[i], index=i, sites=tuple(sites), quat=sent(sig.quat[i]),
                              free_acc=sent(sig.free_acc[i]), acc=sent(sig.specific_force[i]),
                              gyro=sent(sig.gyro[i]), present=present, insole_force=np.full(2, np.nan),
                              contacts=np.zeros(4, bool), insole_present=False))


def truth_recording(path: Path, motion: Motion, sites=SIX, subject: str = "P-001", raw: bool = False,
                    seed: int = 0, drop: tuple[str, ...] = ()) -> Path:
    m = motion.resample(60.0)
    joints = m.joints()
    prob = np.clip(0.5 + 0.5 * truth_contact_values(m.contacts(joints), 60.0), 0.0, 1.0)
    observed = np.zeros(len(SITE_INDEX), dtype=bool)
    observed[[SITE_INDEX[s] for s in sites]] = True
    ticks = itertools.count(0.0, 0.01)
    meta = {"model": "truth (test)", "steps": 0, "sensors": list(sites), "insoles": False,
            "subject": {"id": subject, "height_m": float(m.body.height), "notes": ""},
            "body_height_m": float(m.body.height), "source": "tests/app/report/walks.py"}
    rec = Recorder(path, sites, metadata=meta, flush_interval=1.0, clock=lambda: next(ticks))
    if raw:
        _raw(rec, m, sites, seed, drop)
    for k, i in enumerate(range(0, m.n_frames, 3)):
        fr = PoseFrame(index=k, rot=m.rot[i], root=m.root[i], joints=joints[i], contacts=prob[i] > 0.5,
                       contact_prob=prob[i], features=np.zeros(N_FEATURES), observed=np.zeros(N_FEATURES, bool))
        rec.on_pose(LivePose(fr, t=100.0 + i / 60.0, t_newest=100.0 + i / 60.0, index=k, observed_sites=observed,
                             insoles=False, latency_ms=None, compute_ms=0.0))
    rec.close()
    return path


def walk_recording(path: Path, speed: float = 1.3, seconds: float = 10.0, seed: int = 0, **kw) -> Path:
    return truth_recording(path, generate("walk", speed=speed, seconds=seconds, seed=seed), **kw)


def stand_recording(path: Path, seconds: float = 8.0, **kw) -> Path:
    return truth_recording(path, generate("stand", seconds=seconds), **kw)
