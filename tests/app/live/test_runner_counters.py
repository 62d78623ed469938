"""LivePipeline's counters under load: the ingest thread (queue overflow) and the inference
thread (frames too late) both add to ``stats.dropped``; every frame the source gave is either
pushed or counted dropped, none lost to a race between the two threads."""

from __future__ import annotations

import dataclasses
import sys

import pytest

from app.live import LivePipeline, Pipeline, frames_from_signals
from calibration import Calibrator, Protocol, synthesize_session
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

SITES = ("pelvis", "l_shank", "r_shank")
PROTO = Protocol(table=0.6, strap=0.3, tpose=0.6, blend=0.2, margin=0.1)


class FloodSource:
    """``chunk`` frames per poll, the clip over and over (time running on), ``total`` in all."""

    def __init__(self, frames, chunk: int, total: int) -> None:
        self.frames, self.chunk, self.total = frames, chunk, total
        self.given = 0
        self.span = frames[-1].t - frames[0].t + 1 / 60

    def poll(self):
        out = []
        while len(out) < self.chunk and self.given < self.total:
            k, i = divmod(self.given, len(self.frames))
            f = self.frames[i]
            out.append(dataclasses.replace(f, t=f.t + k * self.span, index=f.index + k * len(self.frames)))
            self.given += 1
        return out


@pytest.fixture(scope="module")
def session():
    sig, truth = synthesize_session(generate("walk", seconds=1.0, seed=2), PROTO, noise=NoiseModel.typical(), rng=3,
                                    sites=SITES)
    return frames_from_signals(sig, t0=100.0), truth.body


def test_every_frame_is_pushed_or_counted_dropped_by_both_threads(session):
    frames, body = session
    old = sys.getswitchinterval()
    total = 20_000
    pipe = Pipeline(make_poser("floor", body=body), SITES, calibrator=Calibrator(SITES, schedule=PROTO.schedule()))
    passed_over = []
    pass_over = pipe.pass_over
    pipe.pass_over = lambda f: (passed_over.append(1), pass_over(f))
    source = FloodSource(frames, chunk=40, total=total)
    live = LivePipeline(pipe, source, queue_size=16, poll_interval=1e-5, max_lag=0.05).start()
    sys.setswitchinterval(1e-6)  # hand the interpreter over as often as it can: a race shows up
    try:
        assert live.wait_for(lambda: source.given >= total and not live._q, 120), live.stats()
        live.wait_for(lambda: pipe.stats.frames_in + pipe.stats.dropped >= total, 10)
    finally:
        sys.setswitchinterval(old)
        live.stop()
    assert live.error is None
    # both threads dropped: the inference thread the late frames it passed over, the ingest thread the rest
    assert len(passed_over) > 0 and pipe.stats.dropped > len(passed_over) and pipe.stats.frames_in > 0
    assert pipe.stats.frames_in + pipe.stats.dropped == total


class HandFedSource:
    """Gives what the test put in, on the next poll."""

    def __init__(self) -> None:
        self.waiting: list = []

    def poll(self):
        out, self.waiting = self.waiting, []
        return out


class FrameTimes:
    def __init__(self) -> None:
        self.t: list[float] = []

    def on_frame(self, frame) -> None:
        self.t.append(frame.t)

    def close(self) -> None:
        pass


@pytest.mark.parametrize("max_lag", [0.15, None])
def test_a_command_takes_effect_where_it_was_given_in_the_stream(session, max_lag):
    """A sink added while frames wait for a busy inference thread gets the frames that came
    after, and one taken off gets those that came before (a recording started and stopped on
    a busy machine holds what was streamed between the two key presses, no more, no less)."""
    import threading

    frames, body = session
    pipe = Pipeline(make_poser("floor", body=body), SITES, calibrator=Calibrator(SITES, schedule=PROTO.schedule()))
    source = HandFedSource()
    live = LivePipeline(pipe, source, poll_interval=1e-3, max_lag=max_lag).start()
    gate, held = threading.Event(), threading.Event()
    sink = FrameTimes()
    try:
        live.call(lambda p: (held.set(), gate.wait(30)))  # the inference thread busy, as with a slow pose
        assert held.wait(10)  # and held before any frame is queued

        def feed(chunk) -> None:
            n = len(live._q)  # noqa: SLF001 - it only grows while the inference thread is held
            source.waiting = list(chunk)
            assert live.wait_for(lambda: len(live._q) == n + len(chunk), 10)  # noqa: SLF001

        feed(frames[:10])
        live.call(lambda p: p.add_sink(sink))
        feed(frames[10:25])
        live.call(lambda p: p.sinks.remove(sink))
        feed(frames[25:30])
        gate.set()
        assert live.wait_for(lambda: not live._q and not live._commands, 10)  # noqa: SLF001
        live.wait_for(lambda: len(sink.t) >= 15, 2)
    finally:
        gate.set()
        live.stop()
    assert live.error is None
    assert sink.t == [f.t for f in frames[10:25]]
