"""A live pipeline told where (``IMUCAP_STALL_TRACE``) writes every thread's stack once the hub has
given no frame for ``STALL_TRACE_S``: the diagnosis of a capture that stalls (NOTES.md, "Tests")."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

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


WATCHER = Path(__file__).parents[3] / "scripts" / "stall_watch.py"


def _wait_for(path: Path, text: str, seconds: float = 30.0) -> str:
    deadline = time.monotonic() + seconds
    while text not in (path.read_text() if path.exists() else "") and time.monotonic() < deadline:
        time.sleep(0.1)
    return path.read_text() if path.exists() else ""


def test_a_hub_that_stops_giving_frames_gets_every_threads_stack_written(tmp_path, monkeypatch):
    prefix = tmp_path / "stall"
    trace = tmp_path / f"stall.{os.getpid()}"  # one file per process
    watcher = subprocess.Popen([sys.executable, str(WATCHER), str(prefix)])
    try:
        live = _pipeline(_frames(0.5)[:30], monkeypatch, prefix).start(warm_up=False)
        try:
            text = _wait_for(trace, "Timeout")  # the list runs out after half a second: the hub "stalls"
            kernel = _wait_for(Path(f"{trace}.proc"), "kernel stack")
        finally:
            live.stop()
    finally:
        watcher.kill()
        watcher.wait()
    assert text.startswith(f"pid {os.getpid()}\n")
    assert "hub frames at " in text
    assert "Timeout (0:00:00.300000)!" in text and "_ingest_loop" in text  # the ingest thread, waiting
    # the threads by kernel id and name, and what the kernel said of each through the stall
    ingest = next(line for line in text.splitlines() if line.startswith("thread ") and "pipeline-ingest" in line)
    tid = ingest.split()[3]
    assert f"=== stall of pid {os.getpid()}" in kernel
    row = next(line for line in kernel.splitlines() if line.startswith(f"{tid} "))
    assert "pipeline-ingest" in row and "ms" in row  # its name, its state and its time on a core

