"""A real, short session recording shared by the replay/export tests: a synthesized walk
(protocol: table, strap, T-pose, activity) streamed as 60 Hz hub frames through the live
Pipeline (calibrating itself from the stream, floor poser) into the HDF5 Recorder, with
6 sensor sites and insoles -- the same path `imucap demo --record` takes, minus the
devices, so it takes about a second."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from app.live import LivePose, Pipeline, frames_from_signals
from app.recording import Recorder
from calibration import Calibrator, Protocol, synthesize_session
from inference.body.body import Body
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

REC_SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
REC_PROTO = Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15)


@dataclass
class RecordedSession:
    path: Path
    live: list[LivePose]
    body: Body
    sites: tuple[str, ...]


@pytest.fixture(scope="session")
def recorded(tmp_path_factory) -> RecordedSession:
    act = generate("walk", seconds=3.0, seed=4)
    sig, truth = synthesize_session(act, REC_PROTO, noise=NoiseModel.typical(), rng=11, sites=REC_SITES)
    body = truth.body
    path = tmp_path_factory.mktemp("rec") / "walk.h5"
    ticks = itertools.count(0.0, 0.01)  # a stepping clock: flushes do not depend on machine speed
    meta = {"model": "floor", "steps": 0, "sensors": list(REC_SITES), "insoles": True,
            "body_height_m": float(body.height), "body_offsets": np.round(body.offsets, 6).tolist()}
    rec = Recorder(path, REC_SITES, metadata=meta, flush_interval=0.2, clock=lambda: next(ticks))
    pipe = Pipeline(make_poser("floor", body=body), REC_SITES,
                    calibrator=Calibrator(REC_SITES, schedule=REC_PROTO.schedule()), sinks=[rec], insoles=True)
    live: list[LivePose] = []
    for f in frames_from_signals(sig, t0=500.0, insoles=True):
        live += pipe.push(f)
    pipe.close()
    assert rec.closed and len(live) > 40
    return RecordedSession(path=path, live=live, body=body, sites=REC_SITES)
