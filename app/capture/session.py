"""A capture from the devices a setup file names: open them, calibrate with the guided
steps, reconstruct live, record.

Real sensors and simulated ones are the same here: a simulated suit (``imucap devices
simulate --setup``) makes its devices appear at the setup's URLs, in its own process, and
this session opens those URLs exactly as it opens a serial port or a CAN bus.

Threads: each device's reader (the hub), the pipeline's inference thread, and the
caller's (terminal or window) which only reads ``status``/``feedback``/``result`` and
calls ``add_marker``/``add_note``/``stop``. A device that stops sending is reported at
once (``on_event`` and the recording's events) and the reconstruction goes on without it;
its driver reconnects when it returns and the samples rejoin at the next hub frame, with
the calibration it had.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app import APP_VERSION
from app.capture.setup_file import Setup
from app.live import LivePipeline, LivePose, Pipeline, Sink, close_sink
from app.live.model_choice import choose_model, keep_up_advice, set_torch_threads
from app.replay import poser_metadata
from calibration import Calibration, GuidedCalibration
from drivers.base import DeviceEvent
from drivers.hub import Hub

INSOLES = "insoles"
SILENT_AFTER_S = 0.5  # a device with no sample for this long is reported as silent


@dataclass
class SessionEvent:
    t: float
    kind: str  # marker, note, device_lost, device_back, device_silent, calibrated, calibration_failed, error
    detail: str = ""


class _Watch(Sink):
    """Counts poses and keeps the latencies; notes the calibration taking effect."""

    def __init__(self, session: CaptureSession) -> None:
        self.session = session
        self.latency: deque[float] = deque(maxlen=600)
        self.pose_times: deque[float] = deque(maxlen=200)
        self.poses = 0

    def on_calibration(self, calibration: Calibration, t: float) -> None:
        self.session._calibrated(calibration, t)

    def on_pose(self, pose: LivePose) -> None:
        self.poses += 1
        self.pose_times.append(time.monotonic())
        if pose.latency_ms is not None:
            self.latency.append(pose.latency_ms)


@dataclass
class CaptureOptions:
    record: Path | None = None
    calibration: Calibration | None = None  # reuse one (``--calibration``) instead of calibrating
    countdown: float = 3.0
    timeout: float = 30.0
    threads: int = 1
    on_event: Callable[[SessionEvent], None] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    sinks: list[Sink] = field(default_factory=list)  # more consumers of the live body: streams (app.streams)
    latency: str = "centred"  # app.live.latency.LATENCY_MODES: "low" waits for no future sample
    confidence: bool = False  # each pose with its per-segment spread (inference/poser/confidence.py)
    reach: bool = True  # a VR rig's tracked hands: the arms reach the controllers (app/live/tracked.py)


def session_spec(setup: Setup, options: CaptureOptions) -> dict[str, Any]:
    """A capture's setup and options as plain data, device URLs by scheme only (their
    paths and ports are the machine's)."""
    return {
        "sensors": {site: e.url.split(":", 1)[0] for site, e in setup.sensors.items()},
        "insoles": None if setup.insoles is None else setup.insoles.split(":", 1)[0],
        **({"tracked": {n: {"scheme": e.url.split(":", 1)[0], "sites": list(e.sites)}
                        for n, e in setup.tracked.items()}} if setup.tracked else {}),
        "subject_height_m": setup.subject.height_m, "model": setup.model, "steps": setup.steps,
        "calibration": setup.calibration, "confidence": bool(options.confidence or setup.confidence),
        "latency": options.latency, "threads": options.threads, "countdown_s": options.countdown,
        "calibration_timeout_s": options.timeout, "record": options.record is not None,
        "reuses_calibration": options.calibration is not None,
        **({"reach": bool(options.reach and setup.reach)} if setup.tracked else {}),
    }


class CaptureSession:
    """One capture of ``setup``'s devices. ``start()`` returns at once; ``stop()`` closes
    the devices and finalises the recording, whatever state the session is in."""

    def __init__(self, setup: Setup, options: CaptureOptions | None = None) -> None:
        from inference.body.body import Body
        from inference.poser.poser import Poser

        self.setup = setup
        self.options = opt = options or CaptureOptions()
        set_torch_threads(opt.threads)
        self.sites = setup.sites()
        choice = choose_model(setup.model, opt.latency, fallback=True, sites=self.sites)
        self.model, self.model_label, self.warning = choice.model, choice.label, choice.warning
        self.model_spec = choice.spec
        causal = choice.causal
        steps = setup.steps
        self.poser = Poser(self.model, body=Body.from_height(setup.subject.height_m), steps=steps, runtime="auto",
                           confidence=opt.confidence or setup.confidence)
        self.guided = GuidedCalibration(self.sites, setup.calibration, countdown=opt.countdown, timeout=opt.timeout)
        self.pipeline = Pipeline(self.poser, self.sites, calibrator=self.guided, insoles=setup.insoles is not None,
                                 clock=time.monotonic, causal=causal, reach=opt.reach and setup.reach)
        self.watch = _Watch(self)
        self.pipeline.add_sink(self.watch)
        for sink in opt.sinks:
            self.pipeline.add_sink(sink)
        self.events: list[SessionEvent] = []
        self.recorder = None
        self.hub: Hub | None = None
        self.live: LivePipeline | None = None
        self.started_at: float | None = None
        self.calibration: Calibration | None = None
        self._state: dict[str, str] = {}
        self._last_seen: dict[str, float] = {}
        self.recording_error: str | None = None

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> CaptureSession:
        import drivers

        # the model's first call builds its runtime (seconds on a busy machine, holding the
        # interpreter): before the devices open and the guided steps' clock starts, not inside
        # the first step. Done after them, it left the serial readers without a turn for a
        # second while the subject held the N-pose, and three of six sensors uncalibrated.
        self.pipeline.warm_up()
        devices = {}
        for name, url in self.setup.urls().items():
            devices[name] = drivers.make_device(url)
        if self.options.record is not None:
            self.start_recording(self.options.record)
        from app.live.latency import hub_options

        self.hub = Hub(devices, **hub_options(self.options.latency), on_event=self._device_event)
        self.started_at = time.monotonic()
        self.guided.reset(self.started_at)
        self.hub.start()
        self._state = {name: "ok" for name in devices}
        if self.options.calibration is not None:
            self.pipeline.set_calibration(self.options.calibration, self.started_at)
        self.live = LivePipeline(self.pipeline, self.hub).start(warm_up=False)
        return self

    def stop(self) -> None:
        if self.live is not None:
            self.live.stop()
        if self.hub is not None:
            self.hub.stop()
        self.stop_recording()
        self.pipeline.close()

    def __enter__(self) -> CaptureSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def spec(self) -> dict[str, Any]:
        """How this session was asked to run (``session_spec``): two front ends that run
        the same capture give the same spec."""
        return session_spec(self.setup, self.options)

    # ------------------------------------------------------------------ recording
    def metadata(self) -> dict[str, Any]:
        s = self.setup
        return {
            "source": "capture", "subject": {"id": s.subject.id, "height_m": s.subject.height_m,
                                             "notes": s.subject.notes},
            "setup": {"sites": {k: e.url for k, e in s.sensors.items()}, "insoles": s.insoles,
                      **({"tracked": {n: e.url for n, e in s.tracked.items()}} if s.tracked else {}),
                      "calibration": s.calibration, "file": str(s.path) if s.path else None},
            "sensors": list(self.sites), "insoles": s.insoles is not None, "model": self.model_label,
            "model_spec": self.model_spec, "app_version": APP_VERSION,
            # how the poser ran, from the poser built: a replay with no options runs it so again
            **poser_metadata(self.poser, self.options.latency),
            "body_height_m": s.subject.height_m, "reach": self.pipeline.reach, **self.options.metadata,
        }

    def start_recording(self, path: str | Path):
        from app.recording import Recorder

        rec = Recorder(path, sites=self.sites, metadata=self.metadata(), on_error=self._recording_failed,
                       position_sites=[s for e in self.setup.tracked.values() for s in e.sites])
        self.recorder = rec

        def attach(p: Pipeline) -> None:
            p.add_sink(rec)
            if p.calibration is not None:  # a recording started after calibrating keeps it
                rec.on_calibration(p.calibration, self.session_time())

        if self.live is not None:
            self.live.call(attach)
        else:
            attach(self.pipeline)
        return rec

    def stop_recording(self) -> Path | None:
        rec, self.recorder = self.recorder, None
        if rec is None:
            return None
        close_sink(self.live, self.pipeline, rec)
        return rec.path

    # ------------------------------------------------------------------ events
    def session_time(self) -> float:
        return time.monotonic()

    def _emit(self, ev: SessionEvent) -> None:
        self.events.append(ev)
        if self.live is not None and self.live.running:
            self.live.call(lambda p: p.event(ev.t, ev.kind, ev.detail))
        else:
            self.pipeline.event(ev.t, ev.kind, ev.detail)
        if self.options.on_event is not None:
            self.options.on_event(ev)

    def add_marker(self, label: str = "") -> SessionEvent:
        ev = SessionEvent(self.session_time(), "marker", label)
        self._emit(ev)
        return ev

    def add_note(self, text: str) -> None:
        self._emit(SessionEvent(self.session_time(), "note", text))

    def _device_event(self, ev: DeviceEvent) -> None:
        """From the hub's reader threads: a device lost or back."""
        tracks = self.hub.tracks.items() if self.hub else ()
        name = next((n for n, tr in tracks if tr.device.device_id == ev.device_id), ev.device_id)
        if ev.kind == "disconnected":
            self._state[name] = "reconnecting"
            self._emit(SessionEvent(ev.t, "device_lost", f"{name}: {ev.detail}"))
        elif ev.kind == "reconnected":
            self._state[name] = "ok"
            self._emit(SessionEvent(ev.t, "device_back", f"{name}: {ev.detail}"))

    def _recording_failed(self, t: float, error: str) -> None:
        """The recorder could not write (disk full, folder gone): say so at once; the live
        view goes on, and what was written opens and replays."""
        self.recording_error = error
        ev = SessionEvent(t, "recording_error", error)
        self.events.append(ev)
        if self.options.on_event is not None:
            self.options.on_event(ev)

    def _calibrated(self, calibration: Calibration, t: float) -> None:
        self.calibration = calibration
        q = calibration.meta.get("quality") or {}
        warnings = list(q.get("warnings", [])) + [w for v in q.get("sensors", {}).values() for w in v["warnings"]]
        detail = "ok" if not warnings else "; ".join(warnings)
        ev = SessionEvent(t, "calibrated", detail)
        self.events.append(ev)
        self.pipeline.event(t, "calibrated", detail)  # already on the pipeline thread
        if self.options.on_event is not None:
            self.options.on_event(ev)

    def poll(self) -> None:
        """Check for silent devices (a link that stays up but sends nothing: out of range,
        battery); called by whoever shows the status, a few times a second."""
        if self.hub is None:
            return
        now = time.monotonic()
        for name, tr in self.hub.tracks.items():
            last = tr.ring.last_t() if len(tr.ring) else (tr.insole[-1][0] if tr.insole else None)
            if last is not None:
                self._last_seen[name] = last
            seen = self._last_seen.get(name)
            silent = seen is None and self.started_at is not None and now - self.started_at > 5.0 or (
                seen is not None and now - seen > SILENT_AFTER_S)
            if silent and self._state.get(name) == "ok":
                self._state[name] = "silent"
                self._emit(SessionEvent(now, "device_silent", f"{name}: no data for {SILENT_AFTER_S:g} s"))
            elif not silent and self._state.get(name) == "silent":
                self._state[name] = "ok"
                self._emit(SessionEvent(now, "device_back", f"{name}: data again"))
        if self.guided.phase == "failed" and not any(e.kind == "calibration_failed" for e in self.events[-3:]):
            self._emit(SessionEvent(now, "calibration_failed", self.guided.error or ""))

    # ------------------------------------------------------------------ status
    def device_states(self) -> dict[str, str]:
        return dict(self._state)

    def fps(self) -> float:
        ts = list(self.watch.pose_times)
        return (len(ts) - 1) / (ts[-1] - ts[0]) if len(ts) > 2 and ts[-1] > ts[0] else 0.0

    def status_line(self, width: int = 100) -> str:
        """One line that fits a laptop terminal: calibration or fps/latency, then each device."""
        if self.calibration is None:
            head = self.guided.status()
        else:
            lat = np.percentile(self.watch.latency, 50) if self.watch.latency else float("nan")
            head = f"{self.fps():4.1f} fps  {lat:4.0f} ms"
            if self.recording_error is not None:
                head += "  REC FAILED"
            elif self.recorder is not None:
                head += "  REC"
        marks = {"ok": "", "reconnecting": "!", "silent": "?"}
        devs = " ".join(f"{n}{marks.get(s, '?')}" for n, s in self._state.items())
        line = f"{head} | {devs}"
        return line if len(line) <= width else line[: width - 1] + "~"

    def result(self) -> dict[str, Any]:
        st = self.live.stats() if self.live is not None else {}
        hub = self.hub.status() if self.hub is not None else {}
        lat = list(self.watch.latency)
        return {
            "frames": self.watch.poses, "fps": round(self.fps(), 2),
            "latency_p50_ms": float(np.percentile(lat, 50)) if lat else None,
            "latency_p99_ms": float(np.percentile(lat, 99)) if lat else None,
            "calibrated": self.calibration is not None,
            "calibration_status": self.guided.status() if self.calibration is None else "calibrated",
            "calibration_quality": (self.calibration.meta.get("quality") if self.calibration else None),
            "devices": {n: {**hub.get(n, {}), "state": self._state.get(n)} for n in hub},
            "events": [{"t": e.t, "kind": e.kind, "detail": e.detail} for e in self.events],
            "pipeline": st, "model": self.model_label,
            "record": str(self.options.record) if self.options.record else None,
            "recording_error": self.recording_error,
            "advice": keep_up_advice(self.watch.poses, self.pipeline.stats.poses_skipped, self.setup.model),
        }
