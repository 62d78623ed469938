"""Session recordings for the report's tests, written by the real Recorder in seconds: the reconstruction
of each is a procedural motion's own truth at 20 Hz (orientations, root, joints, and its heel/toe contacts
as the poser's contact values), so what the report finds can be checked against the motion itself."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from app.live import LivePose
from app.recording import Recorder
from app.report.events import truth_contact_values
from inference.body.motion import Motion
from inference.body.skeleton import SITE_INDEX
from inference.features.layout import N_FEATURES
from inference.poser.poser import PoseFrame
from sim_devices.motions import generate

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")


def truth_recording(path: Path, motion: Motion, sites=SIX, subject: str = "P-001") -> Path:
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
