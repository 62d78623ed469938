"""The live loop keeps up by design: a pose that comes late costs the 20 Hz frames it
overlapped, never a queue. A poser slower than the frame rate, in a real LivePipeline fed
in real time, poses the newest frame each time and reports the ones it skipped."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.live import LivePipeline, Pipeline, frames_from_signals
from app.live.pipeline import POSE_SKIPPED_EVENT, Sink
from calibration import Calibrator, Protocol, synthesize_session
from inference.poser.poser import Poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

SITES = ("pelvis", "l_wrist", "r_wrist", "l_shank", "r_shank")
PROTO = Protocol(table=0.6, strap=0.3, tpose=0.6, blend=0.2, margin=0.1)
T0 = 500.0
STEP_S = 0.12  # the slow poser's step: 2.4 periods of the 20 Hz frame


class SlowPoser(Poser):
    """The floor poser taking ``sleep`` s a step; notes, as each step starts, the newest
    hub frame the pipeline's sinks have been given."""

    def __init__(self, body, seen: list[float], sleep: float = STEP_S) -> None:
        super().__init__(None, body=body)
        self.seen, self.sleep = seen, sleep
        self.at_step: list[float] = []

    def step(self, *args, **kwargs):
        self.at_step.append(self.seen[-1])
        time.sleep(self.sleep)
        return super().step(*args, **kwargs)


class Notes(Sink):
    """The newest hub frame's time (``seen``), the poses, the skipped 20 Hz frames' times."""

    def __init__(self) -> None:
        self.seen: list[float] = []
        self.poses: list = []
        self.skipped: list[float] = []

    def on_frame(self, frame) -> None:
        self.seen.append(frame.t)

    def on_pose(self, pose) -> None:
        self.poses.append(pose)

    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        if kind == POSE_SKIPPED_EVENT:
            self.skipped.append(t)


class RealTimeSource:
    """The frames up to ``head`` s after the first at once (the calibration), the rest as
    their time comes, 60 a second."""

    def __init__(self, frames, head: float) -> None:
        self.frames, self.head, self.i, self.start = frames, head, 0, None

    def poll(self):
        now = time.monotonic()
        if self.start is None:
            self.start = now
        until = self.frames[0].t + self.head + (now - self.start)
        out = []
        while self.i < len(self.frames) and self.frames[self.i].t <= until:
            out.append(self.frames[self.i])
            self.i += 1
        return out

    @property
    def done(self) -> bool:
        return self.i >= len(self.frames)


@pytest.fixture(scope="module")
def session():
    sig, truth = synthesize_session(generate("walk", seconds=3.0, seed=4), PROTO, noise=NoiseModel.typical(), rng=5,
                                    sites=SITES)
    return frames_from_signals(sig, t0=T0), truth.body


def _pipeline(body, sinks, seen, sleep=STEP_S):
    return Pipeline(SlowPoser(body, seen, sleep), SITES, calibrator=Calibrator(SITES, schedule=PROTO.schedule()),
                    sinks=sinks, causal=True)


def test_a_slow_poser_poses_the_newest_frame_and_reports_the_rest(session):
    frames, body = session
    sink = Notes()
    poses, skipped = sink.poses, sink.skipped
    pipe = _pipeline(body, [sink], sink.seen)
    source = RealTimeSource(frames, head=PROTO.calibrated_at + 0.05)
    # the newest hub frame the loop holds (taken from its queue) and the source has given,
    # as each step begins
    taken: list[float] = []
    pipe.poser.seen = taken
    released: list[float] = []
    step = pipe.poser.step
    pipe.poser.step = lambda *a, **k: (released.append(source.frames[source.i - 1].t), step(*a, **k))[1]
    push_newest = pipe.push_newest
    pipe.push_newest = lambda batch: (taken.append(batch[-1].t), push_newest(batch))[1]
    with LivePipeline(pipe, source) as live:
        assert live.wait_for(lambda: source.done and not live._q, 60), live.stats()
        time.sleep(2 * STEP_S)
    assert live.error is None
    st = pipe.stats
    assert pipe.calibration is not None and len(poses) >= 5, st.summary()
    # every pose is of the newest 20 Hz frame the loop held when its step began: with the
    # trailing filter that frame is complete within 2 hub frames of the newest hub frame
    # (a queue worked through starts its steps up to max_lag, 9 hub frames, behind)
    t_pose = np.array([lp.t for lp in poses])
    lag = np.array(pipe.poser.at_step) - t_pose
    assert lag.max() <= 2 / 60 + 1e-6, np.round(lag * 60, 2)
    # and of what the source had given by then, as a rule (frames come in while a batch is
    # read, and a busy machine may hold the loop's thread between the two)
    assert np.median(np.array(released) - t_pose) <= 4 / 60, np.round((np.array(released) - t_pose) * 60, 1)
    # what was skipped is counted and told to the sinks (a recording keeps it)
    assert st.poses_skipped > 0 and len(skipped) == st.poses_skipped
    assert st.poses < 0.6 * (st.poses + st.poses_skipped), st.summary()
    # posed and skipped frames are each 20 Hz frame once, in order, none twice
    times = np.sort(np.r_[[lp.t for lp in poses], skipped])
    assert np.all(np.diff(times) > 1 / 40)
    assert np.all(np.diff([lp.index for lp in poses]) > 0)
    # nothing went missing: frames the loop let go (max_lag) are counted too
    twenty_hz = st.poses + st.poses_skipped
    calibrated = st.frames_in + st.dropped - st.frames_calibrating
    assert abs(twenty_hz - calibrated / 3) <= 3, (twenty_hz, calibrated)


def test_push_newest_poses_the_newest_twenty_hz_frame_only(session):
    frames, body = session
    sink = Notes()
    pipe, every = _pipeline(body, [sink], sink.seen, sleep=0.0), _pipeline(body, [], [0.0], sleep=0.0)
    n_cal = next(k for k, f in enumerate(frames) if pipe.push_newest([f]) or pipe.calibration is not None)
    for f in frames[:n_cal + 1]:
        every.push(f)
    rest = frames[n_cal + 1:n_cal + 1 + 12]  # 12 hub frames: four 20 Hz frames
    out = pipe.push_newest(rest)
    all_poses = [lp for f in rest for lp in every.push(f)]
    assert len(all_poses) == 4 and len(out) == 1
    assert out[0].index == all_poses[-1].index and out[0].t == all_poses[-1].t
    assert pipe.stats.poses_skipped == 3 and sink.skipped == [lp.t for lp in all_poses[:-1]]
    # one frame at a time, as a loop that keeps up takes them: every 20 Hz frame posed
    more = frames[n_cal + 13:n_cal + 13 + 12]
    assert len([lp for f in more for lp in pipe.push_newest([f])]) == 4 and pipe.stats.poses_skipped == 3
