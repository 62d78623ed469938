"""The live chain: hub frames (60 Hz) -> calibration and the optional inputs into one live
frame (``frame.py``) -> 60->20 Hz resampler -> 190-feature observation + mask ->
``Poser.step`` -> the arms' reach onto a VR rig's controllers -> sinks.

``Pipeline`` is the chain without threads: ``push(frame)`` returns the poses that frame
completed (0 or 1), so tests, offline replay and the threaded runner share one code
path. ``LivePipeline`` (``runner.py``) runs it on its own threads (DESIGN.md: inference never runs on
the GUI thread): an ingest thread polls the frame source (the hub) into a bounded queue
(oldest dropped and counted when inference falls behind, so the output describes *now*),
an inference thread drains it through the Pipeline; the GUI only reads ``latest()``.

Acceleration: devices stream *raw* free acceleration and the resampler applies the
model's 11-frame moving average once. The simulated suit replays synthesis's
``meta["free_acc_raw"]`` (sim_devices.devices.base.SignalSource), so nothing here
smooths twice; ``frames_from_signals`` (``sources.py``) follows the same rule for device-less replay.

The optional inputs enter the live frame at one stage (``FrameBuilder``): the insoles'
contacts (``InsoleInput``), a VR rig's positions turned into the model's world with the
calibration's yaw for the rig (``tracked.RigPoints``). The rest of the chain reads the
frame's fields and never asks which inputs exist. After the poser's answer each tracked
hand's arm reaches its controller (``inference.body.reach``); ``reach=False`` leaves the
answer as it is.
"""

from __future__ import annotations

import gc
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from app.live.frame import FrameBuilder, InsoleInput, empty_frame, observation
from app.live.tracked import RigPoints, reach
from calibration import Calibration, Calibrator
from drivers.hub import HubFrame
from inference.body.skeleton import SITE_INDEX
from inference.poser.stride import SHANK_SITES
from inference.signals.resample import StreamingResampler

if TYPE_CHECKING:  # the poser pulls in torch; recorders and replay readers need not
    from inference.poser.poser import PoseFrame, Poser

MAX_FILLED_GAP = 6  # 60 Hz frames; a longer hole restarts the resampler instead of inpainting it
RECALIBRATION_EVENT = "recalibration"
"""The event a pipeline sends its sinks with the first frame that goes back to the
calibrator after a calibration was dropped: from then until the next calibration nothing
is posed."""
POSE_SKIPPED_EVENT = "pose skipped"
"""The event a pipeline sends its sinks for each 20 Hz frame the live loop had no time to
pose (``pass_over``), at that frame's time: a recording keeps them, so that a replay can
leave out the same frames and give back the live reconstruction exactly."""


@dataclass
class LivePose:
    """One reconstructed 20 Hz frame with where it came from.

    t: session time of the 60 Hz sample this frame stands for; t_newest: time of the
    newest sample that went into it (the centred resampler looks 5 samples ahead; from a
    hub, the newest device sample itself, else that grid frame's time);
    observed_sites: (13,) which sites were measured in it; insoles: contacts observed;
    latency_ms: emission time minus t_newest (hub wait + queueing + compute), only for
    live sources; compute_ms: time spent in this push.
    """

    pose: PoseFrame
    t: float
    t_newest: float
    index: int
    observed_sites: np.ndarray
    insoles: bool
    latency_ms: float | None
    compute_ms: float
    # the frame's tracked points (position input, ``inference.body.tracked.point_features``)
    # when the arms reached for them (``Pipeline(reach=...)``), else None
    points: np.ndarray | None = None


def stride_text(status: dict[str, Any]) -> str:
    """``Pipeline.stride_status`` in words for a clinician's screen."""
    if not status["enabled"]:
        return "off"
    if not status["shanks"]:
        return "needs both shanks (walk from the pelvis sensor)" if status.get("odometry") else "needs both shanks"
    if status["scale"] is None:
        return "waiting for the first strides"
    return f"x{status['scale']:.2f} from {status['strides']} strides"


class Sink:
    """Receives what the pipeline produces; override what you need. Called on the
    pipeline's (inference) thread: be quick, or hand over to your own thread."""

    def on_frame(self, frame: HubFrame) -> None:
        """Every 60 Hz hub frame, raw (before calibration)."""

    def on_calibration(self, calibration: Calibration, t: float) -> None:
        """A new calibration took effect at session time ``t``."""

    def on_pose(self, pose: LivePose) -> None:
        """Every reconstructed frame."""

    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        """Something that happened at session time ``t``: a marker, a note, a device lost
        or back (``kind``), with a human-readable ``detail``."""

    def close(self) -> None:
        """End of session."""


class CallbackSink(Sink):
    """A sink from plain callables."""

    def __init__(self, on_pose: Callable[[LivePose], Any] | None = None,
                 on_frame: Callable[[HubFrame], Any] | None = None,
                 on_calibration: Callable[[Calibration, float], Any] | None = None) -> None:
        self._pose, self._frame, self._cal = on_pose, on_frame, on_calibration

    def on_frame(self, frame: HubFrame) -> None:
        if self._frame:
            self._frame(frame)

    def on_calibration(self, calibration: Calibration, t: float) -> None:
        if self._cal:
            self._cal(calibration, t)

    def on_pose(self, pose: LivePose) -> None:
        if self._pose:
            self._pose(pose)


@dataclass
class PipelineStats:
    """Counters (monotonic) and recent timings."""

    frames_in: int = 0
    frames_calibrating: int = 0
    frames_filled: int = 0  # 60 Hz frames missing in the stream, filled as unobserved
    resampler_restarts: int = 0
    poses: int = 0
    poses_skipped: int = 0  # 20 Hz frames of frames passed over (pass_over), not posed
    dropped: int = 0  # set by LivePipeline: frames dropped from its queue
    sink_errors: int = 0
    latency_ms: deque = field(default_factory=lambda: deque(maxlen=2000))
    compute_ms: deque = field(default_factory=lambda: deque(maxlen=2000))
    step_ms: deque = field(default_factory=lambda: deque(maxlen=2000))

    def summary(self) -> dict[str, Any]:
        def pct(d: deque, q: float) -> float | None:
            return round(float(np.percentile(np.fromiter(d, float), q)), 2) if d else None

        return {
            "frames_in": self.frames_in, "frames_calibrating": self.frames_calibrating, "poses": self.poses,
            "poses_skipped": self.poses_skipped, "dropped": self.dropped, "frames_filled": self.frames_filled,
            "resampler_restarts": self.resampler_restarts, "sink_errors": self.sink_errors,
            "latency_p50_ms": pct(self.latency_ms, 50), "latency_p99_ms": pct(self.latency_ms, 99),
            "compute_p50_ms": pct(self.compute_ms, 50), "compute_p99_ms": pct(self.compute_ms, 99),
            "step_p50_ms": pct(self.step_ms, 50), "step_p99_ms": pct(self.step_ms, 99),
        }


class Pipeline:
    """The synchronous chain for frames over ``sites`` (the hub's site order).

    poser: the live Poser. calibration: a ready Calibration, or None to calibrate from
    the stream with ``calibrator`` (default: a Calibrator that waits for ``start_world`` /
    ``start_tpose`` calls). active_sites: the sites whose measurements the poser gets
    (default all of ``sites``): the clinician's sensor configuration, changeable live.
    insoles: use the insoles' contacts. clock: the session clock, for latency (None for
    replay of recorded or synthetic times, where latency means nothing). causal: the
    resampler's trailing moving average (the low-latency mode, ``app.live.latency``); None = the
    filter the poser's model was trained on. reach: the arms of the hands a VR rig tracks
    reach its controllers after the poser's answer (frames with the headset's position and
    at least one controller's); False leaves the answer as the model gave it.
    """

    def __init__(
        self,
        poser: Poser,
        sites: Sequence[str],
        calibration: Calibration | None = None,
        calibrator: Calibrator | None = None,
        active_sites: Sequence[str] | None = None,
        insoles: bool = False,
        sinks: Iterable[Sink] = (),
        clock: Callable[[], float] | None = None,
        causal: bool | None = None,
        reach: bool = True,
    ) -> None:
        self.poser = poser
        self.reach = bool(reach)
        self.sites = tuple(sites)
        unknown = [s for s in self.sites if s not in SITE_INDEX]
        if unknown:
            raise ValueError(f"unknown sensor site(s) {unknown}")
        # the one stage where a hub frame becomes a live frame, optional inputs and all
        self._insoles = InsoleInput()
        self._frames = FrameBuilder(self.sites, [self._insoles, RigPoints(self.sites)])
        self.calibrator = calibrator or Calibrator(self.sites)
        self.calibration: Calibration | None = None
        self.sinks: list[Sink] = list(sinks)
        self.clock = clock
        self.stats = PipelineStats()
        if causal is None:
            causal = getattr(poser, "acc_filter", "centred") == "causal"
        self.causal = bool(causal)
        self.resampler = StreamingResampler(causal=self.causal)
        self._last_index: int | None = None
        # replay: True for the times of 20 Hz frames that are to be left out, as live left
        # them out (app.replay reads them from the recording's POSE_SKIPPED_EVENTs)
        self.skip_pose: Callable[[float], bool] | None = None
        # push_newest: the 20 Hz frames completed so far, waiting for it to pose the newest
        self._pending: list[tuple] | None = None
        # a calibration was in use and has been dropped, and the first frame that went back
        # to the calibrator has not been announced yet (see _calibrating)
        self._had_calibration = False
        self._warmed = False  # warm_up done
        self.set_active_sites(active_sites if active_sites is not None else self.sites, insoles)
        if calibration is not None:
            self.set_calibration(calibration, t=0.0)

    # ------------------------------------------------------------------ configuration
    def set_active_sites(self, sites: Sequence[str], insoles: bool | None = None) -> None:
        """Which sites (and whether the insoles) feed the poser from now on; the others
        become unobserved and are inpainted (no retraining: that is the method's point)."""
        bad = [s for s in sites if s not in self.sites]
        if bad:
            raise ValueError(f"site(s) {bad} are not in this suit ({', '.join(self.sites)})")
        self.active_sites = tuple(s for s in self.sites if s in set(sites))
        self._active = np.isin(self.sites, self.active_sites)
        if insoles is not None:
            self.insoles = bool(insoles)

    @property
    def insoles(self) -> bool:
        """The insoles' contacts feed the poser."""
        return self._insoles.enabled

    @insoles.setter
    def insoles(self, on: bool) -> None:
        self._insoles.enabled = bool(on)

    def add_sink(self, sink: Sink) -> None:
        self.sinks.append(sink)

    def warm_up(self) -> None:
        """The model's first call, its answer thrown away (``Poser.warm_up``): the runtime
        builds its graph and sizes its buffers there rather than on a live frame. Once per
        pipeline: a front end that starts a simulated subject warms up before it (its
        N-pose clock starts with it), and the session's start then finds it done.

        Then what the process holds so far (the model, torch, the modules: ~210,000 objects)
        is frozen out of the garbage collector's full passes (``gc.freeze``). A full pass
        holds the interpreter while it walks every tracked object, and with it every reader
        thread: in a capture with the walk calibration two of them took 96-116 ms each, none
        once frozen (``benchmarks/capture_drops.py`` times a capture's collections). A cycle
        among the frozen objects that becomes garbage later stays until the process ends."""
        if self._warmed:
            return
        warm_up = getattr(self.poser, "warm_up", None)
        if warm_up is not None:
            warm_up()
        gc.collect()
        gc.freeze()
        self._warmed = True

    def set_calibration(self, calibration: Calibration, t: float) -> None:
        """Use ``calibration`` from now on: the poser restarts from a standing history (the
        old one was in another frame of reference) and the resampler from empty."""
        missing = [s for s in self.sites if s not in calibration.sites]
        if missing:
            raise ValueError(f"the calibration has no site(s) {missing}")
        self.calibration = calibration
        self._had_calibration = True
        self.poser.reset()
        self.resampler.reset()
        self._emit("on_calibration", calibration, t)

    def event(self, t: float, kind: str, detail: str = "") -> None:
        """Pass an event to every sink (call on the pipeline's thread: ``LivePipeline.call``)."""
        self._emit("on_event", t, kind, detail)

    def recalibrate(self, origin: float | None = None) -> None:
        """Drop the calibration and collect new windows (schedule re-anchored at ``origin``)."""
        self.calibration = None
        self.calibrator.reset(origin)

    @property
    def status(self) -> str:
        return "calibrated" if self.calibration is not None else self.calibrator.status()

    def stride_status(self) -> dict[str, Any]:
        """What the shank stride scaling of the root is doing (``inference/poser/stride.py``), so
        a screen can say whether the walked distance comes from the shanks yet: enabled
        (the poser has it), shanks (both feed the poser now), scale (None until a stride
        has been measured since calibration) and how many strides were measured; odometry:
        the poser walks the root from the pelvis sensor when the shanks are not both worn
        (``inference/poser/pelvis_odometry.py``). Read from another thread: plain attribute reads
        of the poser's estimator."""
        est = self.poser.stride
        strides = 0 if est is None else len(est.strides)
        return {"enabled": est is not None, "shanks": all(s in self.active_sites for s in SHANK_SITES),
                "scale": round(est.scale, 3) if strides else None, "strides": strides,
                "odometry": self.poser.pelvis_odometry is not None and "pelvis" in self.active_sites}

    # ------------------------------------------------------------------ the chain
    def _emit(self, method: str, *args: Any) -> None:
        for s in self.sinks:
            try:
                getattr(s, method)(*args)
            except Exception:  # a broken sink must not stop the reconstruction
                self.stats.sink_errors += 1
                if self.stats.sink_errors <= 3:
                    traceback.print_exc()

    def push(self, frame: HubFrame) -> list[LivePose]:
        """One 60 Hz hub frame in; the 20 Hz poses it completed out."""
        t_start = time.perf_counter()
        self.stats.frames_in += 1
        if frame.sites != self.sites:
            raise ValueError(f"frame sites {frame.sites} differ from the pipeline's {self.sites}")
        self._emit("on_frame", frame)
        if self._calibrating(frame):
            return []
        return self._take(frame, t_start, pose=True)

    def push_newest(self, frames: Sequence[HubFrame],
                    calls: Sequence[tuple[int, Callable[[Pipeline], Any]]] = ()) -> list[LivePose]:
        """Frames that waited for the live loop, oldest first: each goes in as with ``push``
        (sinks, calibration, resampler), but of the 20 Hz frames they complete only the
        newest is posed; the older ones are skipped as ``pass_over`` skips them
        (``poses_skipped``, ``POSE_SKIPPED_EVENT``), their time already past. A loop that
        keeps up finds one frame at a time and poses every 20 Hz frame; one whose pose came
        late computes the next from the freshest data instead of working through a queue,
        so it is never more than the one late pose behind. ``calls``: ``(k, fn)``, in order,
        ``fn(self)`` run before frame ``k`` (``len(frames)``: after the last, before the pose),
        so that a command given while these frames waited (a recording started or stopped)
        takes effect where it was given in the stream."""
        todo = list(calls)
        self._pending = []
        try:
            for k, f in enumerate(frames):
                run_due(todo, k, self)
                self.push(f)
            run_due(todo, len(frames), self)
        finally:
            pending, self._pending = self._pending, None
        for _index, t20, *_ in pending[:-1]:
            self.stats.poses_skipped += 1
            self._emit("on_event", t20, POSE_SKIPPED_EVENT, "")
        return [self._pose(*pending[-1])] if pending else []

    def _take(self, frame: HubFrame, t_start: float, pose: bool) -> list[LivePose]:
        """A calibrated frame into the resampler (packets lost before it as unobserved
        samples); the 20 Hz frames it completes are posed, or with ``pose`` False skipped."""
        out: list[LivePose] = []
        if self._last_index is not None:
            gap = frame.index - self._last_index - 1
            if 0 < gap <= MAX_FILLED_GAP:
                for k in range(gap):
                    t_fill = frame.t - (gap - k) * (1.0 / 60.0)
                    out += self._resample(t_fill, empty_frame(), t_start, pose=pose)
                self.stats.frames_filled += gap
            elif gap > MAX_FILLED_GAP or gap < 0:
                self.resampler.reset()
                self.stats.resampler_restarts += 1
        self._last_index = frame.index
        live = self._frames.build(frame, self.calibration, self._active)  # type: ignore[arg-type]
        out += self._resample(frame.t, live, t_start, _newest_sample(frame), pose=pose)
        return out

    def pass_over(self, frame: HubFrame) -> None:
        """A frame the live loop has no time to reconstruct: the sinks still get it raw (a
        recording keeps the whole stream, and a replay rebuilds the poses) and a calibration
        in progress still sees it (a still pose with holes reads as motion). After
        calibration it still goes through the resampler, whose moving average spans it, but
        the 20 Hz frames it completes are not posed (``poses_skipped``): left out, it would
        read as lost packets, and the frames around it would be posed blind, with no sensor
        at all, at a cost the loop had just shown it could not pay. Counted as dropped by
        the caller, not as a frame in."""
        self._emit("on_frame", frame)
        if not self._calibrating(frame):
            self._take(frame, time.perf_counter(), pose=False)

    def _calibrating(self, frame: HubFrame) -> bool:
        """Before the first calibration a frame goes to the calibrator (which may finish
        with it); True when it was taken for that."""
        if self.calibration is not None:
            return False
        if self._had_calibration:
            # however the calibration was dropped (recalibrate(), the window's redo), sinks
            # hear when posing stopped: a recording keeps it, so that a replay poses nothing
            # from here until the new calibration, as live
            self._had_calibration = False
            self._emit("on_event", frame.t, RECALIBRATION_EVENT, "")
        self.stats.frames_calibrating += 1
        cal = self.calibrator.push(frame.t, frame.quat, frame.free_acc, frame.acc, frame.gyro, frame.present)
        if cal is not None:
            self.set_calibration(cal, frame.t)
        self._last_index = frame.index
        return True

    def _resample(self, t: float, frame: np.ndarray, t_start: float, newest: float | None = None,
                  pose: bool = True) -> list[LivePose]:
        """A live frame into the resampler (its accelerations averaged, the rest carried with
        the sample each 20 Hz frame stands for); the 20 Hz frames it completes are posed."""
        out = []
        for f20 in self.resampler.push(frame["accelerations"], frame, t):
            t20 = f20.t if f20.t is not None else t
            if not pose or (self.skip_pose is not None and self.skip_pose(t20)):
                self.stats.poses_skipped += 1
                if not pose:
                    self._emit("on_event", t20, POSE_SKIPPED_EVENT, "")
                continue
            frame20 = f20.rest.copy()
            frame20["accelerations"] = f20.acc
            args = (f20.index, t20, t if newest is None else newest, frame20, t_start)
            if self._pending is not None:  # push_newest decides which of them is posed
                self._pending.append(args)
                continue
            out.append(self._pose(*args))
        return out

    def _pose(self, index: int, t: float, t_newest: float, frame: np.ndarray, t_start: float) -> LivePose:
        obs = observation(frame)
        t0 = time.perf_counter()
        points = obs.points
        pose = self.poser.step(obs.x, obs.mask, points)  # a model with a position input reads them
        reached = reach(pose, self.poser.body, points, frame["orientations"], obs.observed) if self.reach else None
        if reached is not None:
            pose = reached
        else:
            points = None
        t1 = time.perf_counter()
        latency = (self.clock() - t_newest) * 1e3 if self.clock is not None else None
        lp = LivePose(pose=pose, t=t, t_newest=t_newest, index=index, observed_sites=obs.observed, insoles=obs.insoles,
                      latency_ms=latency, compute_ms=(t1 - t_start) * 1e3, points=points)
        self.stats.poses += 1
        self.stats.step_ms.append((t1 - t0) * 1e3)
        self.stats.compute_ms.append(lp.compute_ms)
        if latency is not None:
            self.stats.latency_ms.append(latency)
        self._emit("on_pose", lp)
        return lp

    def close(self) -> None:
        self._emit("close")


def _newest_sample(frame: HubFrame) -> float | None:
    """Session time of the newest device sample in a hub frame (None when the frame does
    not say: synthetic and recorded frames)."""
    st = frame.sample_t
    if st is None:
        return None
    st = st[frame.present & np.isfinite(st)]
    return float(st.max()) if st.size else None


def run_due(calls: list[tuple[int, Callable[[Pipeline], Any]]], k: int, pipeline: Pipeline) -> None:
    """Run, and take off the front of ``calls`` (``(k, fn)`` in order), the commands due
    before frame ``k`` (``LivePipeline.call``, ``Pipeline.push_newest``)."""
    while calls and calls[0][0] <= k:
        calls.pop(0)[1](pipeline)
