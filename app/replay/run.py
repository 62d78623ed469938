"""Offline replay of a recorded session: the raw 60 Hz sensor stream of a recording goes
through the same ``Pipeline`` as live (recorded calibration -> resampler -> poser), with
any model, step count and any subset of the recorded sensors.

A researcher re-runs one session many ways ("what would 3 sensors have given?", "the
regressor on the same data?"), so the sensor subset, the insoles and progress reporting
are parameters here, the stream is read into arrays
once (not a Python list of per-frame stacks), and every calibration the session made is
applied at the time it took effect, as it was live (a session recalibrated twice is
replayed in three pieces, the poser restarting from standing at each, as it did).

After a recalibration started, the live pipeline posed nothing until the new calibration
took effect; the recording keeps when that began (the pipeline's ``recalibration`` event),
and a replay poses nothing over the same stretch. Recordings made before the event existed
do not say, and there a replay poses those frames with the previous calibration.

A live loop that falls behind leaves 20 Hz frames unposed (``Pipeline.pass_over``) and the
recording keeps each one's time (the ``pose skipped`` event). The poser is autoregressive,
so every later frame depends on which frames it saw: a replay leaves out the same frames
by default, and gives back the live reconstruction exactly; ``every_frame`` poses them
all instead (a better reconstruction than live had time for, no longer the same one).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from app.live import POSE_SKIPPED_EVENT, RECALIBRATION_EVENT, LivePose, Pipeline, Sink
from app.live.latency import causal_weights
from app.live.model_choice import choose_model
from app.recording import Recording
from app.replay.compare import SAME_FRAME_S, match_times
from calibration import Calibration
from drivers.hub import HubFrame
from inference.body.skeleton import parse_sites
from inference.poser.lag import lagged_frames

if TYPE_CHECKING:
    from inference.poser.poser import Poser


def resolve_sensors(rec: Recording, sensors: str | Sequence[str] | None) -> tuple[str, ...]:
    """The recorded sites to use (default: all of them), in the recording's order. Unknown
    names or sites the recording lacks are a ValueError that lists what it has."""
    if sensors is None:
        return rec.sites
    have = ", ".join(rec.sites) or "none"
    try:
        wanted = parse_sites(sensors)
    except ValueError as exc:
        raise ValueError(f"--sensors: {exc}. This recording has: {have}") from None
    if not wanted:
        raise ValueError(f"--sensors: give at least one site; this recording has: {have}")
    missing = [s for s in wanted if s not in rec.sites]
    if missing:
        raise ValueError(f"--sensors: {', '.join(missing)} not in this recording; it has: {have}")
    return tuple(s for s in rec.sites if s in set(wanted))


def recording_has_insoles(rec: Recording) -> bool:
    ins = rec.raw.get("insoles", {})
    return bool(len(ins.get("present", ())) and np.any(ins["present"]))


def resolve_insoles(rec: Recording, insoles: bool | None) -> bool:
    """Use the insoles? Default: as the session did (metadata ``insoles``), if the recording
    holds insole data at all; asking for them when it does not is a ValueError."""
    has = recording_has_insoles(rec)
    if insoles is None:
        return bool(rec.metadata.get("insoles", has)) and has
    if insoles and not has:
        raise ValueError("--insoles: this recording holds no insole data")
    return bool(insoles)


class _Stream:
    """The raw stream as stacked arrays, yielding HubFrames (views, not copies)."""

    def __init__(self, rec: Recording) -> None:
        r = rec.raw
        self.sites = rec.sites
        self.t = np.asarray(r["t"], dtype=np.float64)
        self.index = np.asarray(r["index"], dtype=np.int64)
        n, S = len(self.t), len(self.sites)

        def stack(name: str, width: int) -> np.ndarray:
            if not S:
                return np.zeros((n, 0, width))
            return np.stack([np.asarray(r[s][name], dtype=np.float64) for s in self.sites], axis=1)

        self.quat = stack("quat", 4)
        self.free_acc, self.acc, self.gyro = stack("free_acc", 3), stack("acc", 3), stack("gyro", 3)
        self.present = (np.stack([np.asarray(r[s]["present"], bool) for s in self.sites], axis=1) if S
                        else np.zeros((n, 0), bool))
        self.position = rec.positions()  # a VR rig's (None when the recording kept none)
        ins = r["insoles"]
        self.force = np.asarray(ins["force"], dtype=np.float64)
        self.contacts = np.asarray(ins["contacts"], dtype=bool)
        self.ins_present = np.asarray(ins["present"], dtype=bool)

    def __len__(self) -> int:
        return len(self.t)

    def frame(self, i: int) -> HubFrame:
        return HubFrame(t=float(self.t[i]), index=int(self.index[i]), sites=self.sites, quat=self.quat[i],
                        free_acc=self.free_acc[i], acc=self.acc[i], gyro=self.gyro[i], present=self.present[i],
                        insole_force=self.force[i], contacts=self.contacts[i], insole_present=bool(self.ins_present[i]),
                        position=None if self.position is None else self.position[i])

    def __iter__(self) -> Iterator[HubFrame]:
        return (self.frame(i) for i in range(len(self)))


@dataclass
class ReplayResult:
    """What a replay produced: the poses (20 Hz, as live) and how it ran."""

    poses: list[LivePose]
    sensors: tuple[str, ...]
    insoles: bool
    hub_frames: int
    calibrations_used: int
    stats: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReplaySettings:
    """How to re-run a recording: what ``imucap replay`` and ``imucap batch`` take. ``None``
    means "as the recording says it ran" (its metadata), else the model file's own."""

    # None: the model the recording was posed with (``recorded_model``); an import and a report's
    # second posing name the full model ("diffusion"): offline, the compute the live default saves
    # buys nothing
    model: str | None = None
    steps: str | None = None
    seed: int | None = None
    mirror: bool | None = None
    stride_scale: bool | None = None
    pelvis_odometry: bool | None = None
    confidence: bool | None = None
    latency: str | None = None
    # frames the shown answer waits for (inference/poser/lag.py); None: as the recording says
    # (a live capture's 0, an imported log's OFFLINE_ANSWER_LAG)
    answer_lag: int | None = None
    # the most of the model's thigh twist a thigh rebuilt from its shank keeps while the body turns
    # (inference/poser/knee_twist.py); None: as the recording says, else the model file's
    knee_twist: float | None = None


@dataclass
class ReplayPoser:
    """A poser built for one recording, and what a summary says of it."""

    poser: Poser
    model: Any  # the LoadedModel (None for the floor)
    causal: bool
    latency: str
    label: str
    steps: int
    warning: str | None = None
    spec: str | None = None  # the model spec it poses with (what a recording's ``model_spec`` names)

    def fresh(self) -> Poser:
        """Another poser of the same settings (one per replay: a poser keeps its history)."""
        from inference.poser.poser import Poser

        return Poser(self.model, body=self.poser.body, **self._setting)

    _setting: dict[str, Any] = field(default_factory=dict)


def poser_metadata(poser: Poser, latency: str) -> dict[str, Any]:
    """How a live session's poser ran, for its recording's metadata: what
    ``build_replay_poser`` reads back, so that a replay with no options runs the poser
    exactly as it ran live (written from the poser that was built, not from the options
    asked for, which may have been defaults)."""
    conf = poser.confidence
    return {
        "steps": len(poser.steps) if poser.kind == "diffusion" else (1 if poser.kind == "regressor" else 0),
        "step_list": [int(k) for k in poser.steps], "seed": int(poser.seed), "mirror": bool(poser.mirror),
        "stride_scale": poser.stride is not None, "pelvis_odometry": poser.pelvis_odometry is not None,
        "confidence": conf is not None, "latency": latency, "answer_lag": int(poser.answer_lag),
        "knee_twist": float(poser.knee_twist),
    }


def recorded_model(meta: dict[str, Any]) -> str:
    """The model spec a recording was posed with: its ``model_spec``, else the shipped file its
    label names (``diffusion 4/128/512 (diffusionposer_fast.pt)``), else "diffusion" (what every
    session recorded before the live default changed ran)."""
    from inference.poser.models import DEFAULT_WEIGHTS

    spec = meta.get("model_spec")
    if spec:
        return str(spec)
    label = str(meta.get("model") or "")
    if label.startswith("floor"):
        return "floor"
    for name, path in DEFAULT_WEIGHTS.items():
        if label.endswith(f"({path.name})"):
            return name
    causal = causal_weights()
    if label.endswith(f"({causal.name})") and causal.exists():
        return str(causal)
    return "diffusion"


def replay_model(rec: Recording, settings: ReplaySettings, sites: Sequence[str] | None = None) -> str:
    """The model spec a replay of ``rec`` wearing ``sites`` (None: every recorded one) poses
    with: ``settings.model``, or the recorded one, with the live default ("auto") turned into
    the shipped file it stands for with those sites. A caller that loads the model once for
    many replays (a batch worker) keys it by this."""
    from inference.poser.models import model_for_sites

    spec = settings.model if settings.model is not None else recorded_model(rec.metadata)
    return str(model_for_sites(spec, rec.sites if sites is None else sites))


def build_replay_poser(rec: Recording, settings: ReplaySettings, body: Any, model: Any = "resolve",
                       sites: Sequence[str] | None = None) -> ReplayPoser:
    """The poser a replay of ``rec`` runs: ``settings`` where given, else what the recording
    says the session ran with (a session recorded before a default changed replays as it
    ran). ``model``: an already loaded model for ``settings.model`` (a batch worker loads
    it once), or "resolve" to load it here. ``sites``: the sensors the replay will wear,
    which the live default ("auto") chooses its file by (None: the recording's)."""
    from inference.poser.poser import Poser

    meta = rec.metadata
    latency = settings.latency or meta.get("latency") or "centred"
    choice = choose_model(replay_model(rec, settings, sites), latency, loaded=model)
    loaded, causal, warning, label = choice.model, choice.causal, choice.warning, choice.label
    # the step list and mirror averaging the session ran (a model file's defaults may have changed since),
    # unless asked otherwise; another model than the recorded one runs its own file's
    same_model = label == meta.get("model")
    mirror = settings.mirror if settings.mirror is not None else (meta.get("mirror") if same_model else None)
    stride = settings.stride_scale if settings.stride_scale is not None else bool(meta.get("stride_scale", False))
    odometry = (settings.pelvis_odometry if settings.pelvis_odometry is not None
                else bool(meta.get("pelvis_odometry", False)))
    steps = settings.steps if settings.steps is not None else (meta.get("step_list") or None if same_model else None)
    seed = settings.seed if settings.seed is not None else int(meta.get("seed") or 0)
    confidence = settings.confidence if settings.confidence is not None else bool(meta.get("confidence", False))
    lag = settings.answer_lag if settings.answer_lag is not None else int(meta.get("answer_lag") or 0)
    if loaded is None or loaded.kind != "diffusion":
        lag = 0  # one pass or none: no window answers the frames before its newest
    twist = settings.knee_twist if settings.knee_twist is not None else meta.get("knee_twist")
    if twist is None and "step_list" in meta:
        twist = 0.0  # posed before the knee's twist existed: the strict hinge it ran with
    setting = dict(steps=steps, seed=seed, mirror=mirror, stride_scale=stride,
                   pelvis_odometry="default" if odometry else None, confidence=confidence or None, answer_lag=lag,
                   knee_twist=twist)
    poser = Poser(loaded, body=body, **setting)
    steps = len(poser.steps) if poser.kind == "diffusion" else (1 if poser.kind == "regressor" else 0)
    return ReplayPoser(poser, loaded, causal, latency, label, steps, warning, spec=choice.spec,
                       _setting=setting)


def replay_recording(rec: Recording, poser: Poser, sensors: str | Sequence[str] | None = None,
                     insoles: bool | None = None, calibration: Calibration | None = None,
                     progress: Callable[[int, int, int], None] | None = None, sinks: Sequence[Sink] = (),
                     pace: Callable[[float], None] | None = None, causal: bool | None = None,
                     every_frame: bool = False, reach: bool | None = None) -> ReplayResult:
    """Run ``rec``'s raw stream through a Pipeline with ``poser``.

    sensors: the recorded sites whose measurements the poser gets (default all; the
    others are inpainted, as live with a smaller suit); insoles: see ``resolve_insoles``;
    calibration: use this one from the first frame instead of the recorded ones;
    progress(done_frames, total_frames, poses) is called about every 1% of the stream.
    sinks: get the replay as a live session's sinks would (frames, calibrations, poses,
    and the recorded events at their times), and are closed at the end; pace(t) is called
    before the frame of time ``t`` is pushed (``app.streams.pacing.Pacer`` holds it back
    to real time). causal: the trailing acceleration filter of the low-latency mode (None:
    the one the poser's model was trained on). every_frame: also pose the frames the live
    loop had no time for (default: leave them out, as live did). reach: the arms reach a VR
    rig's recorded controllers after each answer (``Pipeline(reach=...)``; None: as the
    session did, its metadata's ``reach``, on when it does not say).
    """
    use = resolve_sensors(rec, sensors)
    ins = resolve_insoles(rec, insoles)
    if calibration is None and not rec.calibrations:
        if any(line.startswith("calibration") for line in rec.damage):
            raise ValueError(f"{rec.path}: its calibration is damaged (see the warnings); nothing to replay")
        raise ValueError(f"{rec.path} holds no calibration (the session never calibrated); nothing to replay")
    cals = [(-np.inf, calibration)] if calibration is not None else sorted(rec.calibrations, key=lambda c: c[0])
    # when a live recalibration stopped the posing (a calibration given here holds throughout)
    recals = [] if calibration is not None else sorted(ev[0] for ev in rec.events if ev[1] == RECALIBRATION_EVENT)
    stream = _Stream(rec)
    reach = bool(rec.metadata.get("reach", True)) if reach is None else bool(reach)
    pipe = Pipeline(poser, rec.sites, active_sites=use, insoles=ins, sinks=sinks, causal=causal, reach=reach)
    skipped = live_skipped_times(rec)
    if len(skipped) and not every_frame:
        pipe.skip_pose = lambda t20: bool(match_times(np.array([t20]), skipped, SAME_FRAME_S)[0] >= 0)
    events = sorted(rec.events, key=lambda e: e[0]) if sinks else []
    e = 0  # next event to pass on
    poses: list[LivePose] = []
    k = 0  # next calibration to apply
    r = 0  # next recalibration start
    paused = False
    used = 0
    n = len(stream)
    every = max(n // 100, 1)
    for i in range(n):
        t = stream.t[i]
        if pace is not None:
            pace(float(t))
        while e < len(events) and events[e][0] <= t:
            pipe.event(*events[e])
            e += 1
        took_effect_now = False
        while (k < len(cals) and t >= cals[k][0]) or (r < len(recals) and t >= recals[r]):
            if r < len(recals) and t >= recals[r] and (k >= len(cals) or recals[r] <= cals[k][0]):
                paused = True  # live, this frame went back to the calibrator
                r += 1
                continue
            pipe.set_calibration(cals[k][1], float(max(cals[k][0], t)))
            took_effect_now = took_effect_now or t == cals[k][0]  # live, that frame was the last calibrating one
            paused = False
            k += 1
            used += 1
        if paused or took_effect_now:
            # live, the pipeline consumed this frame while calibrating and noted its index, so
            # the next frame is not taken for a dropped one
            pipe._last_index = int(stream.index[i])
        elif pipe.calibration is not None:
            poses += pipe.push(stream.frame(i))
        if progress is not None and (i % every == 0 or i == n - 1):
            progress(i + 1, n, len(poses))
    for ev in events[e:]:
        pipe.event(*ev)
    pipe.close()
    if poser.answer_lag:
        # each frame as the window answer_lag frames later answered it (inference/poser/lag.py);
        # the sinks saw the live answers as they came
        lagged = lagged_frames([p.pose for p in poses], poser.body)
        poses = [replace(p, pose=f) for p, f in zip(poses, lagged)]
    return ReplayResult(poses=poses, sensors=use, insoles=ins, hub_frames=n, calibrations_used=used,
                        stats=pipe.stats.summary())


def live_skipped_times(rec: Recording) -> np.ndarray:
    """Sorted times of the 20 Hz frames the live loop had no time to pose."""
    return np.array(sorted(ev[0] for ev in rec.events if ev[1] == POSE_SKIPPED_EVENT), dtype=float)
