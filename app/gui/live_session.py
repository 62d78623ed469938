"""A running capture as the window reads it: device rows, calibration feedback, frame
rate, events, recording, with the simulated devices it may have started.

Why an adapter: ``CaptureSession`` speaks to a terminal and to tests; the window wants
per-device rates and "last seen", new events since it last looked, and a place to keep
the simulated devices' process it started for the demo, stopped with the session.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.capture.session import INSOLES, CaptureSession, SessionEvent
from app.live import LivePose, Sink
from calibration.guided import GuidedFeedback
from calibration.quality import QualityReport
from inference.body.body import Body

RATE_WINDOW_S = 1.0
# While calibrating, the pipeline's thread only feeds the guided steps (no model), so it can
# always catch up; dropping frames to stay current (what the live view wants) would
# instead leave holes that the stillness measure reads as motion, and on a busy machine
# a step then never holds. Frames are kept for this long until the calibration is done.
CALIBRATION_MAX_LAG_S = 2.0
STOP_CATCH_UP_S = 3.0  # the most "Stop recording" waits for the pipeline to reach the click


class _LastFrame(Sink):
    """The session time of the newest frame the pipeline has handled (its thread writes,
    others read one float)."""

    def __init__(self) -> None:
        self.t = float("-inf")

    def on_frame(self, frame) -> None:
        self.t = frame.t


@dataclass
class DeviceRow:
    name: str  # the site, or "insoles"
    url: str
    state: str  # ok, reconnecting, silent, waiting
    rate_hz: float | None
    loss_pct: float | None  # of its samples, lost on the way or too late for their frames (not recorded)
    battery: float | None
    last_seen_s: float | None  # seconds since its last sample
    packets: int
    reconnects: int


class LiveSession:
    """Owns a CaptureSession (and the simulated devices' process, if the window started one)."""

    def __init__(self, session: CaptureSession, simulation: Any = None) -> None:
        self.session = session
        self.simulation = simulation
        self.setup = session.setup
        self.sites = session.sites
        self.body = Body.from_height(session.setup.subject.height_m)
        self.started = False
        self._rates: dict[str, tuple[float, int, float | None]] = {}  # name -> (t, packets, rate)
        self._seen_events = 0
        self._live_max_lag: float | None = None
        self.record_path: Path | None = None
        self.record_started: float | None = None
        self._last_frame = _LastFrame()
        session.pipeline.add_sink(self._last_frame)

    # ------------------------------------------------------------------ lifecycle (worker threads)
    def start(self) -> LiveSession:
        try:
            self.session.start()
        except BaseException:
            self.stop()
            raise
        self.started = True
        rec = self.session.recorder
        if rec is not None:  # asked for when the session was made (``--record``)
            self.record_path, self.record_started = rec.path, time.monotonic()
        live = self.session.live
        self._live_max_lag = live.max_lag if live is not None else None
        self._keep_frames_while_calibrating()
        return self

    def _keep_frames_while_calibrating(self) -> None:
        live = self.session.live
        if live is None:
            return
        want = self._live_max_lag if self.calibrated else CALIBRATION_MAX_LAG_S
        if live.max_lag != want:
            live.max_lag = want

    def spec(self) -> dict[str, Any]:
        """How the capture and its simulator (if any) were asked to run: the headless demo's
        ``DemoSpec.describe()`` for the window's demo."""
        sim = self.simulation
        return {"session": self.session.spec(), "simulator": sim.spec() if hasattr(sim, "spec") else None}

    def stop(self) -> Path | None:
        path = self.record_path if self.session.recorder is not None else None
        try:
            self.session.stop()
        finally:
            if self.simulation is not None:
                self.simulation.stop()
        return path

    def add_sink(self, sink: Sink) -> None:
        live = self.session.live
        if live is not None and live.running:
            live.call(lambda p: p.add_sink(sink))
        else:
            self.session.pipeline.add_sink(sink)

    # ------------------------------------------------------------------ what the window reads
    def latest(self) -> LivePose | None:
        live = self.session.live
        return live.latest() if live is not None else None

    @property
    def calibrated(self) -> bool:
        return self.session.calibration is not None

    def feedback(self) -> GuidedFeedback:
        return self.session.guided.feedback()

    @property
    def report(self) -> QualityReport | None:
        return self.session.guided.report

    @property
    def error(self) -> str | None:
        live = self.session.live
        if live is not None and live.error is not None:
            return f"the reconstruction stopped: {live.error!r}"
        rec = self.session.recorder
        if rec is not None and rec.error:
            return rec.error
        return None

    def poll(self) -> list[SessionEvent]:
        """Look for silent devices, and return the events since the last call."""
        self.session.poll()
        if self.started:
            self._keep_frames_while_calibrating()
        evs = self.session.events
        new = evs[self._seen_events:]
        self._seen_events += len(new)
        return list(new)

    def perf(self) -> dict[str, Any]:
        s = self.session
        lat = sorted(s.watch.latency)
        st = s.live.stats() if s.live is not None else {}
        return {"fps": s.fps(), "latency_ms": lat[len(lat) // 2] if lat else None,
                "dropped": int(st.get("dropped", 0)), "skipped": int(st.get("poses_skipped", 0)),
                "frames": s.watch.poses}

    def device_rows(self) -> list[DeviceRow]:
        s = self.session
        hub = s.hub
        urls = self.setup.urls()
        if hub is None:
            return [DeviceRow(n, u, "waiting", None, None, None, None, 0, 0) for n, u in urls.items()]
        states = s.device_states()
        status = hub.status()
        now = time.monotonic()
        rows = []
        for name, tr in hub.tracks.items():
            st = status.get(name, {})
            packets = int(st.get("packets", 0))
            t0, p0, rate = self._rates.get(name, (now, packets, None))
            if now - t0 >= RATE_WINDOW_S:
                rate = (packets - p0) / (now - t0)
                self._rates[name] = (now, packets, rate)
            elif name not in self._rates:
                self._rates[name] = (now, packets, None)
            lost = int(st.get("lost", 0))
            # a sample that came after its frame was put out is in neither the poses nor the recording
            late = min(int(st.get("late", 0)), packets)
            loss = 100.0 * (lost + late) / (packets + lost) if packets + lost else None
            if name == INSOLES:
                last = tr.insole[-1][0] if tr.insole else None
            else:
                last = tr.ring.last_t() if len(tr.ring) else None
            seen = None if last is None else max(0.0, now - last)
            rows.append(DeviceRow(name, urls.get(name, ""), states.get(name, "ok"), rate, loss, st.get("battery"),
                                  seen, packets, int(st.get("reconnects", 0))))
        return rows

    def set_active_sites(self, sites: tuple[str, ...], insoles: bool) -> None:
        """The worn sensors the reconstruction uses from now on (the others are inpainted);
        on the pipeline's thread, between two frames."""
        live = self.session.live
        if live is not None and live.running:
            live.call(lambda p: p.set_active_sites(sites, insoles))
        else:
            self.session.pipeline.set_active_sites(sites, insoles)

    def active_sites(self) -> tuple[str, ...]:
        return tuple(self.session.pipeline.active_sites)

    # ------------------------------------------------------------------ calibration
    def redo(self, step: str) -> None:
        """Start calibration again at ``step``: on the pipeline's thread, where the
        guided calibration is fed."""
        s = self.session

        def on_pipeline(p) -> None:
            p.calibration = None
            s.guided.redo(step)

        s.calibration = None
        if s.live is not None and s.live.running:
            s.live.call(on_pipeline)
        else:
            on_pipeline(s.pipeline)

    # ------------------------------------------------------------------ recording
    @property
    def recording(self) -> bool:
        return self.session.recorder is not None

    def start_recording(self, folder: Path | None = None) -> Path:
        """A new file named after the subject and the time; creating it is the one step
        that can fail here (an OSError the window shows)."""
        folder = Path(folder or self.setup.recordings_dir())
        folder.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        path = folder / f"{self.setup.subject.id}-{stamp}.h5"
        k = 1
        while path.exists():
            k += 1
            path = folder / f"{self.setup.subject.id}-{stamp}-{k}.h5"
        self.session.start_recording(path)
        self.record_path, self.record_started = path, time.monotonic()
        return path

    def stop_recording(self) -> Path | None:
        """Waits for the pipeline thread to close the file: call it off the GUI thread.

        The pipeline runs behind the sensors (the hub's latency, a model step, a busy
        machine); the file is closed once it has handled the frames up to the moment Stop
        was pressed, so the recording ends where the user ended it, not a second early."""
        until = time.monotonic()
        give_up = until + STOP_CATCH_UP_S
        live = self.session.live
        while live is not None and live.running and self._last_frame.t < until and time.monotonic() < give_up:
            time.sleep(0.02)
        path = self.session.stop_recording()
        self.record_started = None
        return path

    def add_marker(self, label: str) -> SessionEvent:
        return self.session.add_marker(label)

    def add_note(self, text: str) -> None:
        self.session.add_note(text)
