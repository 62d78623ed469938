"""The recording that guards the live frame's layout: a short VR-rig walk (an IMU at the pelvis,
the rig at the head and wrists with positions), insoles, a site that drops out and a gap of
lost packets, recorded through the live Pipeline into the Recorder and posed by a tiny
seeded diffusion model with a position input (so every channel of the frame reaches the
answer: orientations, accelerations, which sites are observed, contacts, tracked points
and the arms' reach).

``tests/app/live/data/frame_guard.h5`` (the recording), ``frame_guard.pt`` (the model) and
``frame_guard.npz`` (a replay's poses) were written by this module with the pipeline that
packed the frame into one float vector by hand-kept offsets (commit 8d6e054):

    .venv/bin/python -m tests.app.live.frame_fixture tests/app/live/data

``test_frame_guard.py`` replays the recording with today's code and wants the same poses.
Written once: running this again with today's code would only compare the code with itself.
"""

from __future__ import annotations

import dataclasses
import itertools
import sys
from pathlib import Path

import numpy as np

SEED = 7


def tiny_model(path: Path) -> None:
    import torch

    from inference.features.layout import N_FEATURES
    from inference.model.config import ModelConfig
    from inference.model.files import build_model, save_model

    torch.manual_seed(SEED)
    cfg = dataclasses.replace(ModelConfig.tiny(), mask_input=True, points=True)
    net = build_model("diffusion", cfg)
    with torch.no_grad():  # the position input starts at zero: make it count
        torch.nn.init.normal_(net.points_proj.weight, std=0.2)
    save_model(path, net, "diffusion", np.zeros(N_FEATURES), np.ones(N_FEATURES))


def guard_frames():
    """The rig walk's hub frames with insoles, r_wrist absent for a while and packets lost."""
    from tests.app.rig_frames import rig_walk

    rig = rig_walk(seconds=3.0, seed=4)
    frames = []
    for f in rig.frames:
        i = f.index
        if 100 <= i < 103:  # lost packets: the pipeline fills them as unobserved
            continue
        present = f.present.copy()
        if 60 <= i < 75:
            present[3] = False
        contacts = np.array([(i // 20) % 2 == 0, (i // 15) % 2 == 0, (i // 20) % 2 == 1, (i // 25) % 2 == 1])
        frames.append(dataclasses.replace(f, present=present, contacts=contacts, insole_present=True,
                                          insole_force=np.array([300.0, 250.0])))
    return rig, frames


def write(out: Path) -> None:
    from app.live import Pipeline
    from app.recording import Recorder, read_recording
    from app.replay import replay_recording
    from inference.poser.poser import make_poser
    from tests.app.rig_frames import RIG_SITES, SITES

    out.mkdir(parents=True, exist_ok=True)
    model = out / "frame_guard.pt"
    tiny_model(model)
    rig, frames = guard_frames()
    path = out / "frame_guard.h5"
    ticks = itertools.count(0.0, 0.01)
    rec = Recorder(path, SITES, metadata={"model": str(model.name), "steps": 2, "insoles": True,
                                          "sensors": list(SITES), "body_height_m": float(rig.motion.body.height)},
                   flush_interval=0.2, clock=lambda: next(ticks), position_sites=RIG_SITES)
    pipe = Pipeline(make_poser(model, body=rig.motion.body, steps=2, seed=0), SITES, sinks=[rec], insoles=True)
    pipe.set_calibration(rig.calibration, frames[0].t - 0.01)
    live = []
    for f in frames:
        live += pipe.push(f)
    pipe.close()
    r = read_recording(path)
    res = replay_recording(r, make_poser(model, body=rig.motion.body, steps=2, seed=0))
    np.savez_compressed(out / "frame_guard.npz", **poses_arrays(res.poses),
                        live_rot=np.stack([lp.pose.rot for lp in live]))


def poses_arrays(poses) -> dict[str, np.ndarray]:
    return {"t": np.array([lp.t for lp in poses]), "rot": np.stack([lp.pose.rot for lp in poses]),
            "root": np.stack([lp.pose.root for lp in poses]), "joints": np.stack([lp.pose.joints for lp in poses]),
            "observed": np.stack([lp.observed_sites for lp in poses]),
            "insoles": np.array([lp.insoles for lp in poses]),
            "reached": np.array([lp.points is not None for lp in poses])}


if __name__ == "__main__":
    write(Path(sys.argv[1]))
