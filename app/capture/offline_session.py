"""A session recording written from synthesized signals without devices or waiting.

Why: batch re-processing, its benchmark and its tests need many recordings of chosen
lengths, and a capture from simulated devices runs in real time (20 recordings of a
minute would take 20 minutes). The hub frames a capture would record come here from the
synthesized signals directly (``frames_from_signals``), through the live ``Pipeline``
(calibrating itself from the table protocol in the stream) into the ``Recorder``: the
same file a capture writes, in about a second per minute of motion with the floor poser.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from app.live import Pipeline, frames_from_signals
from app.recording import Recorder
from calibration import Calibrator, Protocol, synthesize_session
from inference.body.motion import Motion
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
PROTOCOL = Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15)


def write_session(path: str | Path, seconds: float, seed: int = 0, sites: tuple[str, ...] = SIX,
                  motion: str = "walk", insoles: bool = False, model: str = "floor") -> Path:
    """Write a recording of ``seconds`` of ``motion`` (after a short table calibration) at
    ``path``; the live reconstruction in it is ``model``'s (the floor by default: cheap)."""
    from sim_devices.motions import generate

    record_motion(path, generate(motion, seconds=seconds, seed=seed), sites, rng=seed, t0=100.0 + seed,
                  insoles=insoles, model=model)
    return Path(path)


def record_motion(path: str | Path, act: Motion, sites: tuple[str, ...], rng: int = 0, t0: float = 100.0,
                  insoles: bool = False, model: str = "floor", flush_interval: float = 1.0) -> Motion:
    """Record ``act`` after the table calibration at ``path`` (its first hub frame at session
    time ``t0``, the sensor noise drawn with ``rng``); returns the session's truth, the motion
    as the sensors followed it (calibration poses included), for tests and benchmarks that
    score the recording against it."""
    sig, truth = synthesize_session(act, PROTOCOL, noise=NoiseModel.typical(), rng=rng, sites=sites)
    body = truth.body
    ticks = itertools.count(0.0, 0.01)  # a stepping clock: flushes do not depend on machine speed
    meta = {"model": model, "steps": 0, "sensors": list(sites), "insoles": insoles,
            "body_height_m": float(body.height), "body_offsets": np.round(body.offsets, 6).tolist(),
            "source": "simulated (app/capture/offline_session.py)"}
    rec = Recorder(path, sites, metadata=meta, flush_interval=flush_interval, clock=lambda: next(ticks))
    pipe = Pipeline(make_poser(model, body=body), sites, calibrator=Calibrator(sites, schedule=PROTOCOL.schedule()),
                    sinks=[rec], insoles=insoles)
    for f in frames_from_signals(sig, t0=t0, insoles=insoles):
        pipe.push(f)
    pipe.close()
    return truth
