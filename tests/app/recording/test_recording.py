"""Recording: write a session incrementally, read it back, replay it; and a recorder killed
with SIGKILL leaves a readable file up to its last flush."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from app.live import Pipeline, frames_from_signals
from app.recording import Recorder, read_recording
from app.replay import replay_recording
from calibration import Calibrator, Protocol, synthesize_session
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

REPO = Path(__file__).resolve().parents[3]
SITES = ("pelvis", "l_wrist", "r_wrist", "l_shank")
PROTO = Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15)


@pytest.fixture(scope="module")
def session():
    act = generate("squat", seconds=2.0, seed=3)
    sig, truth = synthesize_session(act, PROTO, noise=NoiseModel.typical(), rng=5, sites=SITES)
    return sig, truth


def test_write_read_replay(tmp_path, session):
    sig, truth = session
    path = tmp_path / "s.h5"
    poser = make_poser("floor", body=truth.body)
    # a clock that advances 10 ms per reading: the flush count must not depend on how fast this machine is
    ticks = itertools.count(0.0, 0.01)
    rec = Recorder(path, SITES, metadata={"model": "floor", "steps": 0, "sensors": list(SITES)}, flush_interval=0.05,
                   clock=lambda: next(ticks))
    pipe = Pipeline(poser, SITES, calibrator=Calibrator(SITES, schedule=PROTO.schedule()), sinks=[rec], insoles=True)
    frames = frames_from_signals(sig, t0=10.0, insoles=True)
    live = []
    for f in frames:
        live += pipe.push(f)
    pipe.close()
    assert rec.closed and rec.flushes > 3 and live

    r = read_recording(path)
    assert r.sites == SITES and r.metadata["model"] == "floor"
    assert r.n_frames == len(frames)
    k = SITES.index("l_wrist")
    assert np.allclose(r.raw["l_wrist"]["quat"], sig.quat[:, k], atol=1e-6)
    assert np.allclose(r.raw["t"], [f.t for f in frames])
    assert r.raw["insoles"]["present"].all()
    assert len(r.calibrations) == 1
    t_cal, cal = r.calibrations[0]
    assert np.allclose(cal.R_SB, pipe.calibration.R_SB) and np.array_equal(cal.valid, pipe.calibration.valid)
    assert len(r.recon["t"]) == len(live)
    assert np.allclose(r.recon["R"], np.stack([lp.pose.rot for lp in live]), atol=1e-5)
    assert np.allclose(r.recon["root"], np.stack([lp.pose.root for lp in live]), atol=1e-5)
    # replay of the raw stream with the recorded calibration reproduces the reconstruction
    again = replay_recording(r, make_poser("floor", body=truth.body)).poses
    assert len(again) == len(live)
    assert np.allclose(np.stack([lp.pose.rot for lp in again]), np.stack([lp.pose.rot for lp in live]), atol=1e-4)


CHILD = r"""
import sys, time, numpy as np
sys.path.insert(0, {repo!r})
from drivers.hub import HubFrame
from app.recording import Recorder
sites = ("pelvis", "head")
rec = Recorder({path!r}, sites, metadata={{"who": "child"}}, flush_interval=0.1)
i = 0
last = 0
while True:
    q = np.tile([1.0, 0, 0, 0], (2, 1))
    v = np.full((2, 3), float(i))
    rec.on_frame(HubFrame(t=i / 60, index=i, sites=sites, quat=q, free_acc=v, acc=v, gyro=v,
                          present=np.ones(2, bool), insole_force=np.zeros(2), contacts=np.zeros(4, bool),
                          insole_present=False))
    i += 1
    if rec.flushes != last:
        last = rec.flushes
        print("flushed", rec.frames, flush=True)
    time.sleep(0.002)
"""


def test_killed_recorder_leaves_a_readable_file(tmp_path):
    path = tmp_path / "killed.h5"
    code = CHILD.format(repo=str(REPO), path=str(path))
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=REPO)
    flushed = 0
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            flushed = int(line.split()[1])
            if flushed >= 150:
                break
        assert flushed >= 150, "the child never flushed"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    r = read_recording(path)
    n = r.n_frames
    assert n >= flushed  # everything flushed before the kill is there...
    assert np.array_equal(r.raw["index"], np.arange(n))  # ...consistent, in order
    assert np.allclose(r.raw["head"]["free_acc"][:, 0], np.arange(n))
    assert r.metadata == {"who": "child"} and json.loads(r.attrs["sites"]) == ["pelvis", "head"]


def test_writes_from_several_threads_while_flushing(tmp_path, session):
    """Frames arrive on the pipeline's thread, device events on the readers', and a session
    stops from its own: every row written whole, none lost, however they interleave."""
    import threading

    sig, truth = session
    frames = frames_from_signals(sig, t0=10.0, insoles=True)
    rec = Recorder(tmp_path / "t.h5", SITES, metadata={"model": "floor"}, flush_interval=0.0)
    stop = threading.Event()
    events = [0]

    def device_events() -> None:
        while not stop.is_set():
            rec.on_event(10.0 + events[0] * 1e-3, "device_lost", "pelvis")
            events[0] += 1
            time.sleep(1e-4)

    th = threading.Thread(target=device_events)
    th.start()
    try:
        for f in frames:
            rec.on_frame(f)  # flush_interval 0: every frame flushes, with events landing in between
    finally:
        stop.set()
        th.join(10)
    rec.close()
    r = read_recording(tmp_path / "t.h5")
    assert r.n_frames == len(frames) and not r.damage
    assert len(r.events) == events[0] > 0


def test_each_dataset_caches_only_the_chunks_being_written(tmp_path):
    """HDF5 2.0 gives every dataset an 8 MiB chunk cache; a recording of ~40 growing
    datasets then held what it wrote in memory (+93 MB over an hour's soak). Every dataset
    the recorder writes keeps at most CHUNKS_CACHED of its own chunks, full ones evicted
    first; what a long session costs is measured by benchmarks/soak.py --malloc."""
    import h5py

    from app.recording.writer import CHUNKS_CACHED

    rec = Recorder(tmp_path / "r.h5", sites=("pelvis", "l_wrist"), metadata={})
    try:
        datasets = [*rec._raw.values(), *rec._cal.values(), *rec._rec.values(), *rec._ev.values()]
        assert len(datasets) > 20
        for ds in datasets:
            assert isinstance(ds, h5py.Dataset)
            chunk_bytes = int(np.prod(ds.chunks)) * ds.dtype.itemsize
            _, nbytes, w0 = ds.id.get_access_plist().get_chunk_cache()
            assert nbytes == CHUNKS_CACHED * chunk_bytes and w0 == 1.0, ds.name
    finally:
        rec.close()
