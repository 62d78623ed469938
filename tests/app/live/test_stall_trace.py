"""A live pipeline told where (``IMUCAP_STALL_TRACE``) writes every thread's stack once the hub has
given no frame for ``STALL_TRACE_S``: the diagnosis of a capture that stalls (NOTES.md, "Tests")."""

from __future__ import annotations

import time

from app.live import LivePipeline, Pipeline, frames_from_signals
from app.live import runner as live_runner
from app.live.sources import ListSource
from calibration import Calibrator, Protocol, synthesize_session
from inference.poser.poser import Poser
from sim_devices.motions import generate

SITES = ("pelvis", "l_shank", "r_shank")
PROTO = Protocol(table=0.4, strap=0.2, tpose=0.4, blend=0.1, margin=0.1)


def _pipeline(frames, monkeypatch, path) -> LivePipeline:
    monkeypatch.setenv(live_runner.STALL_TRACE_ENV, str(path))
    monkeypatch.setattr(live_runner, "STALL_TRACE_S", 0.3)
    poser = Poser(None, body=1.75)
    pipe = Pipeline(poser, SITES, calibrator=Calibrator(SITES, schedule=PROTO.schedule()))
    return LivePipeline(pipe, ListSource(frames, realtime=True))


def _frames(seconds: float):
    sig, _ = synthesize_session(generate("walk", seconds=seconds, seed=2), PROTO, rng=3, sites=SITES)
    return frames_from_signals(sig, t0=100.0)


def test_a_hub_that_stops_giving_frames_gets_every_threads_stack_written(tmp_path, monkeypatch):
    trace = tmp_path / "stall.txt"
    live = _pipeline(_frames(0.5)[:30], monkeypatch, trace).start(warm_up=False)
    try:
        deadline = time.monotonic() + 30.0
        while "Timeout" not in (trace.read_text() if trace.exists() else "") and time.monotonic() < deadline:
            time.sleep(0.1)  # the list runs out after half a second: the hub "stalls"
    finally:
        live.stop()
    text = trace.read_text()
    assert text.startswith("hub frames at ")
    assert "Timeout (0:00:00.300000)!" in text and "_ingest_loop" in text  # the ingest thread, waiting

