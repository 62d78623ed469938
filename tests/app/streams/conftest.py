"""Real poses for the stream tests, and a receiver to catch what the OSC sinks send.

``suit``: a synthesized session (table, strap, T-pose, a 3 s walk) of all 13 sites as
60 Hz hub frames, run through the live Pipeline (calibrating itself from the stream,
floor poser) by ``run_pipeline`` with the sinks under test; ``walk_poses``: LivePoses
straight from the synthesized walk (forward kinematics of its rotations and root), whose
root moves, unlike the floor poser's.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import ThreadingOSCUDPServer

from app.live import CallbackSink, LivePose, Pipeline, frames_from_signals
from calibration import Calibrator, Protocol, synthesize_session
from drivers.hub import HubFrame
from inference.body.body import Body, forward_kinematics
from inference.body.motion import Motion
from inference.body.skeleton import N_CONTACTS, SITES
from inference.features.layout import N_FEATURES
from inference.poser.poser import PoseFrame, make_poser
from sim_devices.motions import generate

PROTO = Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15)


@dataclass
class Suit:
    frames: list[HubFrame]
    sites: tuple[str, ...]
    body: Body
    truth: Motion
    activity_start: float


@pytest.fixture(scope="session")
def suit() -> Suit:
    act = generate("walk", seconds=3.0, seed=4)
    sig, truth = synthesize_session(act, PROTO, rng=11, sites=SITES)
    return Suit(frames=frames_from_signals(sig, t0=1000.0), sites=tuple(SITES), body=truth.body, truth=truth,
                activity_start=float(sig.meta["activity_start"]))


def run_pipeline(suit: Suit, sinks: Sequence) -> tuple[list[LivePose], Pipeline]:
    """Every frame of ``suit`` through a fresh Pipeline with ``sinks`` (not closed)."""
    poses: list[LivePose] = []
    pipe = Pipeline(make_poser("floor", body=suit.body), suit.sites,
                    calibrator=Calibrator(suit.sites, schedule=PROTO.schedule()),
                    sinks=[*sinks, CallbackSink(on_pose=poses.append)])
    for f in suit.frames:
        pipe.push(f)
    assert pipe.stats.sink_errors == 0
    return poses, pipe


@pytest.fixture(scope="session")
def walk_poses(suit) -> list[LivePose]:
    m = suit.truth
    start = int(round(suit.activity_start * m.fps))
    out = []
    for k, i in enumerate(range(start, m.n_frames, 3)):
        R, root = m.rot[i], m.root[i]
        pf = PoseFrame(index=k, rot=R, root=root, joints=forward_kinematics(R, root, m.body.offsets),
                       contacts=np.array([k % 2 == 0, True, False, k % 3 == 0]), contact_prob=np.full(N_CONTACTS, .5),
                       features=np.zeros(N_FEATURES), observed=np.zeros(N_FEATURES, bool))
        out.append(LivePose(pose=pf, t=2000.0 + i / m.fps, t_newest=2000.0 + i / m.fps, index=k,
                            observed_sites=np.ones(len(SITES), bool), insoles=False, latency_ms=None,
                            compute_ms=0.0))
    assert len(out) > 40 and np.ptp([p.pose.root[0] for p in out]) > 0.5  # it walks
    return out


class OscInbox:
    """A python-osc server on a free loopback port that keeps every message it gets."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, tuple]] = []
        self._lock = threading.Lock()
        d = Dispatcher()
        d.set_default_handler(self._keep)
        self.server = ThreadingOSCUDPServer(("127.0.0.1", 0), d)
        self.port = self.server.server_address[1]
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self._thread.start()

    def _keep(self, address: str, *args) -> None:
        with self._lock:
            self.messages.append((address, args))

    def count(self, address: str) -> int:
        with self._lock:
            return sum(1 for a, _ in self.messages if a == address)

    def wait_for(self, address: str, n: int, timeout: float = 5.0) -> None:
        end = time.monotonic() + timeout
        while self.count(address) < n:
            assert time.monotonic() < end, f"got {self.count(address)} of {n} {address}"
            time.sleep(0.001)

    def frames(self, first: str) -> list[list[tuple[str, tuple]]]:
        """The messages split into frames, each starting at a ``first`` message."""
        out: list[list[tuple[str, tuple]]] = []
        with self._lock:
            for m in self.messages:
                if m[0] == first:
                    out.append([])
                if out:
                    out[-1].append(m)
        return out

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def inbox():
    box = OscInbox()
    yield box
    box.close()


class Barrier(CallbackSink):
    """After the sink under test, waits until the receiver has the whole frame, so frames
    cannot interleave in the (threaded) receiver."""

    def __init__(self, box: OscInbox, last: str) -> None:
        self.n = 0

        def wait(_pose: LivePose) -> None:
            self.n += 1
            box.wait_for(last, self.n)

        super().__init__(on_pose=wait)
