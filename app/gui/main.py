"""The imucap window: set up a subject, assign and watch the devices, calibrate, watch and
record live, replay, re-run and export, in one window with a tab per job.

Threads: the capture session, the device readers of "move the sensor you want", replays,
exports and scans all run on their own threads (``workers.Jobs``); the window only reads
what they produce on QTimers (the pose at 30 Hz, devices and calibration at 10 Hz), so a
device that hangs or a model that loads never freezes it. Errors land in the message bar
at the top, never only on the console.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtGui, QtWidgets

from app.capture.session import CaptureOptions, CaptureSession, SessionEvent
from app.capture.setup_file import Setup, SetupError, Subject
from app.gui.calibration_panel import CalibrationPanel
from app.gui.devices_panel import DevicesPanel
from app.gui.gui_cost import GuiCost
from app.gui.live_panel import LivePanel
from app.gui.live_session import LiveSession
from app.gui.outdoor_view import SKELETONS, OutdoorView
from app.gui.recordings_panel import RecordingsPanel
from app.gui.replay_panel import ReplayPanel
from app.gui.setup_model import SetupModel
from app.gui.setup_panel import SetupPanel
from app.gui.signal_tap import SignalTap
from app.gui.widgets import MessageBar, fmt
from app.gui.workers import Jobs
from app.live.gait import GaitSink

TABS = ("Setup", "Devices", "Calibration", "Live", "Recordings", "Replay", "Outdoor")
ALARM_KINDS = ("device_lost", "device_silent")
MAX_DRAW_GAP_S = 0.25  # a congested window still redraws the skeleton at least 4 times a second
# the live loop is behind when its poses come this late (smoothed; the headless demo's p99 on
# an idle 2-core machine is ~90 ms): the view then redraws at MAX_DRAW_GAP_S, because with
# software GL a redraw costs the model's threads CPU they are short of (benchmarks/window_live.py)
BEHIND_MS = 150.0


def default_settings() -> QtCore.QSettings:
    return QtCore.QSettings("imucap", "imucap")


class MainWindow(QtWidgets.QMainWindow):
    def __init__(self, settings: QtCore.QSettings | None = None, ui_hz: float = 30.0) -> None:
        super().__init__()
        self.settings = settings if settings is not None else default_settings()
        self.setWindowTitle("imucap")
        self.resize(1280, 800)
        self.jobs = Jobs(self)
        self.model = SetupModel(self)
        self.session: LiveSession | None = None
        self.simulation: Any = None  # the simulated devices' process ("Simulate devices", the demo)
        self.sim_urls: set[str] = set()
        self.down: dict[str, str] = {}  # device -> why, while it is lost or silent
        self.alarm_log: list[tuple[float, str]] = []  # when each alarm was shown (monotonic)
        self.starting = False

        central = QtWidgets.QWidget()
        lay = QtWidgets.QVBoxLayout(central)
        lay.setContentsMargins(4, 4, 4, 4)
        self.messages = MessageBar()
        lay.addWidget(self.messages)
        self.tabs = QtWidgets.QTabWidget()
        lay.addWidget(self.tabs, 1)
        self.setCentralWidget(central)

        self.setup_panel = SetupPanel(self.model, self.report)
        self.devices_panel = DevicesPanel(self.model, self.jobs, self.report)
        self.calibration_panel = CalibrationPanel()
        self.live_panel = LivePanel()
        self.recordings_panel = RecordingsPanel(self.jobs, self.report)
        self.replay_panel = ReplayPanel(self.jobs, self.report)
        # the live view for a glance from a distance (app/gui/outdoor_view.py); its skeleton as last chosen
        skeleton = str(self.settings.value("outdoor/skeleton", "2d"))
        self.outdoor = OutdoorView(skeleton=skeleton if skeleton in SKELETONS else "2d")
        self.live_tab = "Live"  # where the window goes once calibrated
        self.gait: GaitSink | None = None
        for name, panel in zip(TABS, (self.setup_panel, self.devices_panel, self.calibration_panel, self.live_panel,
                                      self.recordings_panel, self.replay_panel, self.outdoor)):
            self.tabs.addTab(panel, name)

        self.setup_panel.fileChanged.connect(lambda p: self.settings.setValue("setup/last_file", p))
        self.devices_panel.simulateRequested.connect(self.simulate_devices)
        self.calibration_panel.redoRequested.connect(self.redo)
        self.live_panel.recordToggled.connect(self.set_recording)
        self.outdoor.recordToggled.connect(self.set_recording)
        self.outdoor.skeletonChosen.connect(lambda kind: self.settings.setValue("outdoor/skeleton", kind))
        self.live_panel.markerRequested.connect(self.add_marker)
        self.live_panel.noteRequested.connect(self.add_note)
        self.live_panel.activeSitesChosen.connect(self.set_active_sites)
        self.recordings_panel.openRequested.connect(self.open_replay)
        self.model.changed.connect(self._setup_changed)

        # --- toolbar and status bar
        tb = self.addToolBar("Session")
        tb.setMovable(False)
        tb.setObjectName("session-toolbar")
        self.start_action = tb.addAction("▶ Start capture", self.start_capture)
        self.stop_action = tb.addAction("■ Stop", self.stop_capture)
        self.stop_action.setEnabled(False)
        tb.addSeparator()
        self.session_label = QtWidgets.QLabel("no capture")
        tb.addWidget(self.session_label)
        sb = self.statusBar()
        self.fps_label, self.latency_label, self.dropped_label, self.rec_label = (QtWidgets.QLabel() for _ in range(4))
        for w in (self.rec_label, self.fps_label, self.latency_label, self.dropped_label):
            sb.addPermanentWidget(w)
        self._show_perf(None)

        # --- shortcuts: R record, M marker, Space play/pause
        QtGui.QShortcut(QtGui.QKeySequence("R"), self, activated=self._record_key)
        QtGui.QShortcut(QtGui.QKeySequence("M"), self, activated=self._marker_key)
        QtGui.QShortcut(QtGui.QKeySequence("Space"), self, activated=self._space_key)

        # --- timers
        self.cost = GuiCost()  # what the window itself takes (--window-stats)
        self.loop_lag = 0.0  # how late the view timer arrives, smoothed (s)
        self.pose_lag_ms = 0.0  # how late the live poses come, smoothed (BEHIND_MS)
        self._draw_tick = self._drawn_at = time.monotonic()
        self._slow_ticks = 0
        self.view_timer = QtCore.QTimer(self)
        self.view_timer.timeout.connect(self._draw)
        self.view_timer.start(int(1000 / ui_hz))
        self.status_timer = QtCore.QTimer(self)
        self.status_timer.timeout.connect(self._status)
        self.status_timer.start(100)
        self.slow_timer = QtCore.QTimer(self)
        self.slow_timer.timeout.connect(self._slow_status)
        self.slow_timer.start(250)
        self._restore()

    # ------------------------------------------------------------------ messages
    def report(self, text: str, level: str = "info") -> None:
        """Every error and notice goes here: the bar at the top of the window."""
        self.messages.show_message(text, level)
        if level in ("error", "warning"):
            print(f"imucap: {text}", file=sys.stderr)

    # ------------------------------------------------------------------ settings
    def _restore(self) -> None:
        geo = self.settings.value("window/geometry")
        if isinstance(geo, QtCore.QByteArray) and not geo.isEmpty():
            self.restoreGeometry(geo)
        tab = self.settings.value("window/tab")
        if tab in TABS:
            self.tabs.setCurrentIndex(TABS.index(tab))
        follow = self.settings.value("live/follow")
        if follow is not None:
            self.live_panel.follow.setChecked(str(follow).lower() in ("true", "1"))

    def save_settings(self) -> None:
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.setValue("window/tab", TABS[self.tabs.currentIndex()])
        self.settings.setValue("live/follow", self.live_panel.follow.isChecked())
        self.settings.sync()

    def open_last_setup(self) -> bool:
        last = self.settings.value("setup/last_file")
        if last and Path(str(last)).exists():
            return self.setup_panel.open(str(last))
        return False

    def _setup_changed(self) -> None:
        self.recordings_panel.set_folder(self._recordings_dir())

    def _recordings_dir(self) -> Path:
        d = self.model.draft
        if d.recordings.is_absolute() or d.path is None:
            return d.recordings
        return d.path.parent / d.recordings

    # ------------------------------------------------------------------ simulated devices
    def simulate_devices(self, protocol: str) -> None:
        """Simulated sensors at the chosen sites, started now so they can be checked and
        identified; the capture restarts them so the subject begins with the protocol."""
        from app.capture.twins import simulated_setup
        from app.gui.simulated import start_simulation

        d = self.model.draft
        if not d.sites:
            self.report("choose the sites first (Setup tab), then simulate their devices", "warning")
            return
        setup = simulated_setup(d.sites, protocol, d.insoles, model=d.model, steps=d.steps,
                                subject=Subject(d.subject_id.strip() or "sim-01", d.height_m, d.notes))
        for site, e in setup.sensors.items():
            self.model.add_device(e.url, f"simulated {protocol}", "simulated")
            self.model.assign(site, e.url)
        if setup.insoles:
            self.model.update(insoles_url=setup.insoles)
        self._stop_simulation()
        self.sim_urls = set(setup.urls().values())
        self.report(f"starting {len(setup.sensors)} simulated devices…", "info")
        self.jobs.run("simulate", start_simulation, setup, on_done=self._simulation_started,
                      on_error=lambda e: self.report(f"simulated devices failed to start: {e}", "error"))

    def _simulation_started(self, sim: Any) -> None:
        self.simulation = sim
        self.report(f"{len(sim.urls)} simulated devices running: start the capture when ready", "ok")

    def _stop_simulation(self) -> None:
        sim, self.simulation = self.simulation, None
        if sim is not None:
            self.jobs.run("simulate-stop", sim.stop)

    # ------------------------------------------------------------------ the capture session
    def start_capture(self) -> None:
        if self.session is not None or self.starting:
            return
        try:
            setup = self.model.to_setup()
        except SetupError as exc:
            self.report(str(exc), "error")
            self.tabs.setCurrentIndex(TABS.index("Devices" if "no device" in str(exc) else "Setup"))
            return
        sim = self.simulation if self.simulation is not None and set(setup.urls().values()) <= self.sim_urls \
            else None
        if sim is None:
            self._stop_simulation()
        self.simulation = None
        self.devices_panel.cancel_identification()
        self._start(setup, None, sim)

    def adopt_session(self, session: CaptureSession, simulation: Any = None) -> None:
        """A session built elsewhere (``imucap capture --setup`` with a display): show its
        setup and start it here."""
        self.model.load(session.setup)
        self._start(session.setup, session, simulation, restart_simulation=False)

    def _start(self, setup: Setup, session: CaptureSession | None, simulation: Any,
               restart_simulation: bool = True, options: CaptureOptions | None = None,
               make_simulation: Any = None) -> None:
        """Build (the model loads) and start the session on a worker thread. A simulation
        is (re)started last, right before the devices are opened, so the simulated subject
        begins with the calibration steps as the wizard does."""
        self.starting = True
        self.start_action.setEnabled(False)
        self.session_label.setText("starting: opening devices, loading the model…")
        self.report("starting the capture: opening the devices and loading the model…", "info")

        def run() -> LiveSession:
            s = session or CaptureSession(setup, options or CaptureOptions())
            sim = simulation
            try:
                s.pipeline.warm_up()  # before a simulated subject's clock starts (DemoRun.start); once
                if make_simulation is not None:
                    sim = make_simulation()
                elif sim is not None and restart_simulation:
                    sim.restart()
            except BaseException:
                s.stop()
                raise
            return LiveSession(s, sim).start()

        self.jobs.run("start", run, on_done=self._started, on_error=self._start_failed)

    def _started(self, live: LiveSession) -> None:
        self.starting = False
        self.session = live
        self.down = {}
        tap = SignalTap(live.sites)
        live.add_sink(tap)
        self.gait = GaitSink()
        live.add_sink(self.gait)
        self.live_panel.attach(tap, live.sites, insoles=live.setup.insoles is not None)
        self._enable_record(True)
        if live.recording and live.record_path is not None:
            self._show_recording(True, f"recording {live.record_path.name}")
        self.calibration_panel.set_protocol(live.setup.calibration, live.session.guided.still_dps,
                                            live.session.guided.moved_dps)
        self.devices_panel.set_session_running(True)
        self.stop_action.setEnabled(True)
        self.start_action.setEnabled(False)
        self.session_label.setText(f"capturing {live.setup.subject.id}: {len(live.sites)} sensors"
                                   f"{' + insoles' if live.setup.insoles else ''}, model {live.session.model_label}")
        if live.session.warning:
            self.report(live.session.warning, "warning")
        else:
            self.report("capture running: follow the calibration steps", "ok")
        if not live.calibrated and self.tabs.currentIndex() in (0, 1, 4, 5):
            self.tabs.setCurrentIndex(TABS.index("Calibration"))

    def _start_failed(self, exc: BaseException) -> None:
        self.starting = False
        self.start_action.setEnabled(True)
        self.session_label.setText("no capture")
        self.report(f"the capture could not start: {exc}", "error")

    def stop_capture(self) -> None:
        live, self.session = self.session, None
        if live is None:
            return
        self.stop_action.setEnabled(False)
        self.session_label.setText("stopping…")
        self._enable_record(False)
        self.jobs.run("stop", live.stop, on_done=self._stopped,
                      on_error=lambda e: (self._stopped(None), self.report(f"stopping: {e}", "error")))

    def _stopped(self, recorded: Path | None) -> None:
        self.start_action.setEnabled(True)
        self.session_label.setText("no capture")
        self.devices_panel.set_session_running(False)
        self._show_recording(False, "not recording")
        self.messages.clear_alarm()
        self.down = {}
        self.calibration_panel.show_idle("Capture stopped")
        self.calibration_panel.set_redo_enabled(True)
        self._show_perf(None)
        self.report("capture stopped" + (f"; recorded {recorded}" if recorded else ""), "ok")
        self.recordings_panel.refresh()

    # ------------------------------------------------------------------ calibration
    def redo(self, step: str) -> None:
        if self.session is None:
            self.report("no capture running", "warning")
            return
        self.session.redo(step)
        self.report(f"redoing from '{step}': {self.session.feedback().prompt}", "info")
        self.tabs.setCurrentIndex(TABS.index("Calibration"))

    # ------------------------------------------------------------------ recording
    def _show_recording(self, on: bool, text: str) -> None:
        self.live_panel.set_recording(on, text)
        self.outdoor.set_recording(on, text)

    def _enable_record(self, on: bool) -> None:
        self.live_panel.record_button.setEnabled(on)
        self.outdoor.set_record_enabled(on)

    def show_outdoor(self) -> None:
        """The outdoor view (``--view outdoor``): what a runner reads from a distance; also
        where the window goes once calibrated."""
        self.live_tab = "Outdoor"
        if self.tabs.currentWidget() is not self.calibration_panel:
            self.tabs.setCurrentIndex(TABS.index("Outdoor"))

    def set_recording(self, on: bool) -> None:
        live = self.session
        if live is None:
            self._show_recording(False, "no capture running")
            return
        if on == live.recording:
            return
        self._enable_record(False)
        if on:
            self.jobs.run("record-start", live.start_recording, on_done=self._recording_started,
                          on_error=self._recording_failed)
        else:
            self.jobs.run("record-stop", live.stop_recording, on_done=self._recording_stopped,
                          on_error=self._recording_failed)

    def _recording_started(self, path: Path) -> None:
        self._enable_record(True)
        self._show_recording(True, f"recording {path.name}")
        self.live_panel.add_event(f"{time.strftime('%H:%M:%S')} recording to {path}")
        self.report(f"recording to {path}", "ok")

    def _recording_stopped(self, path: Path | None) -> None:
        self._enable_record(True)
        self._show_recording(False, f"saved {path.name}" if path else "not recording")
        if path:
            self.live_panel.add_event(f"{time.strftime('%H:%M:%S')} saved {path}")
            self.report(f"saved {path}", "ok")
        self.recordings_panel.refresh()

    def _recording_failed(self, exc: BaseException) -> None:
        self._enable_record(self.session is not None)
        self._show_recording(False, "not recording")
        self.report(f"recording: {exc}", "error")

    def add_marker(self, label: str) -> None:
        if self.session is None:
            self.report("markers need a running capture", "warning")
            return
        self.session.add_marker(label)

    def add_note(self, text: str) -> None:
        if self.session is None:
            self.report("notes need a running capture", "warning")
            return
        self.session.add_note(text)

    def set_active_sites(self, sites: tuple[str, ...], insoles: bool) -> None:
        if self.session is None:
            return
        if not sites:
            self.report("keep at least one sensor for the reconstruction", "warning")
            return
        self.session.set_active_sites(sites, insoles)
        self.report(f"reconstructing from {', '.join(sites)}{' + insoles' if insoles else ''}", "info")

    def _record_key(self) -> None:
        if self.session is not None and self.live_panel.record_button.isEnabled():
            self.live_panel.record_button.toggle()

    def _marker_key(self) -> None:
        if self.session is not None:
            self.live_panel.request_marker()

    def _space_key(self) -> None:
        if self.tabs.currentWidget() is self.replay_panel:
            self.replay_panel.toggle_play()

    # ------------------------------------------------------------------ replay
    def open_replay(self, path: str) -> None:
        self.replay_panel.open(path)
        self.tabs.setCurrentIndex(TABS.index("Replay"))

    # ------------------------------------------------------------------ timers
    def _draw(self) -> None:
        """The newest pose into the view, as often as the event loop keeps up: every redraw
        of a GL view recomposes the window (a round trip to the display server), so when
        the timer itself arrives late (a busy machine, software GL) the view is redrawn
        less often rather than leaving no time for the alarms and the buttons; and when the
        poses themselves come late (the model short of CPU), the view gives way to it."""
        now = time.monotonic()
        late = max(now - self._draw_tick - self.view_timer.interval() / 1000.0, 0.0)
        self._draw_tick = now
        self.loop_lag = 0.8 * self.loop_lag + 0.2 * late
        self.cost.lag_ms.append(late * 1e3)
        live = self.session
        lp = live.latest() if live is not None else None
        if lp is not None and lp.latency_ms is not None:
            self.pose_lag_ms = 0.9 * self.pose_lag_ms + 0.1 * lp.latency_ms
        gap = MAX_DRAW_GAP_S if self.pose_lag_ms > BEHIND_MS else min(MAX_DRAW_GAP_S, 4.0 * self.loop_lag)
        if now - self._drawn_at < gap:
            return
        panel = self.outdoor if self.tabs.currentWidget() is self.outdoor else self.live_panel
        if live is not None and live.body is not None and panel.show_pose(lp, live.body):
            self._drawn_at = now
            self.cost.drew(now, (time.monotonic() - now) * 1e3)

    def _status(self) -> None:
        """10 Hz: events (devices lost and back first: they are the alarms) and the
        calibration's feedback."""
        live = self.session
        if live is None:
            return
        t0 = time.monotonic()
        try:
            self._status_now(live)
        finally:
            self.cost.status_ms.append((time.monotonic() - t0) * 1e3)

    def _status_now(self, live: LiveSession) -> None:
        for ev in live.poll():
            self._event(ev)
        err = live.error
        if err and err != getattr(self, "_last_error", None):
            self._last_error = err
            self.report(err, "error")
        if not live.calibrated:
            f = live.feedback()
            g = live.session.guided
            self.calibration_panel.show_feedback(f, g.error if g.phase == "failed" else None, g.countdown_s)
        else:
            self.calibration_panel.show_done(live.report)

    def _slow_status(self) -> None:
        live = self.session
        if live is None:
            return
        # hidden tabs are not redrawn: on a busy machine every millisecond of the GUI thread
        # is one the devices' and the model's threads do not get
        rows = live.device_rows()
        self.devices_panel.show_live(rows, redraw=self.tabs.currentWidget() is self.devices_panel)
        if self.tabs.currentWidget() is self.outdoor and self.gait is not None:
            self.outdoor.show_numbers(self.gait.numbers())
            self.outdoor.show_devices(rows)
        self._slow_ticks += 1
        congested = self.loop_lag > 0.05
        if self.tabs.currentWidget() is self.live_panel and (not congested or self._slow_ticks % 4 == 0):
            self.live_panel.update_plots()
        if self._slow_ticks % 4 == 0:  # once a second: each label change repaints the window too
            self._show_perf(live.perf())
        if live.recording and live.record_started is not None:
            self._show_recording(True, f"recording {live.record_path.name if live.record_path else ''} "
                                                f"{time.monotonic() - live.record_started:5.1f} s")
            self.rec_label.setText("● REC")
            self.rec_label.setStyleSheet("color: #d02020; font-weight: bold")
        else:
            self.rec_label.setText("")

    def _show_perf(self, perf: dict[str, Any] | None) -> None:
        perf = perf or {}
        self.fps_label.setText(f"{fmt(perf.get('fps'), '.1f')} frames/s")
        self.latency_label.setText(f"latency {fmt(perf.get('latency_ms'), '.0f', ' ms')}")
        # dropped: hub frames the loop let go; skipped: 20 Hz poses it had no time for
        self.dropped_label.setText(f"dropped {perf.get('dropped', 0)}, skipped {perf.get('skipped', 0)}")

    def _event(self, ev: SessionEvent) -> None:
        stamp = time.strftime("%H:%M:%S")
        words = ev.kind.replace("_", " ")
        self.live_panel.add_event(f"{stamp} {words}: {ev.detail}" if ev.detail else f"{stamp} {words}",
                                  alarm=ev.kind in ALARM_KINDS or ev.kind in ("error", "calibration_failed"))
        name = ev.detail.split(":", 1)[0]
        if ev.kind in ALARM_KINDS:
            self.down[name] = ev.detail
            self._alarm()
        elif ev.kind == "device_back":
            self.down.pop(name, None)
            if self.down:
                self._alarm()
            else:
                self.messages.clear_alarm(then=f"{name} is back")
        elif ev.kind == "calibrated":
            level = "ok" if ev.detail == "ok" else "warning"
            self.report("calibrated" + ("" if ev.detail == "ok" else f": {ev.detail}"), level)
            if self.tabs.currentWidget() is self.calibration_panel:
                self.tabs.setCurrentIndex(TABS.index(self.live_tab))
        elif ev.kind == "calibration_failed":
            self.report(f"calibration failed: {ev.detail}", "error")

    def _alarm(self) -> None:
        names = ", ".join(sorted(self.down))
        why = "; ".join(self.down.values())
        why = why if len(why) <= 240 else why[:239] + "…"
        if len(self.down) == 1:
            text = (f"DEVICE DROPPED OUT: {names}. The reconstruction goes on without it; check its cable, "
                    f"battery or range ({why})")
        else:
            text = (f"DEVICES DROPPED OUT: {names}. The reconstruction goes on without them; check their cables, "
                    f"batteries or range ({why})")
        self.messages.alarm(text)
        self.alarm_log.append((time.monotonic(), names))
        self.devices_panel.show_live(self.session.device_rows() if self.session else [])

    # ------------------------------------------------------------------ closing
    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 (Qt's name)
        self.save_settings()
        for t in (self.view_timer, self.status_timer, self.slow_timer):
            t.stop()
        self.devices_panel.cancel_identification()
        live, self.session = self.session, None
        if live is not None:
            self.jobs.run("stop", live.stop)
        self._stop_simulation()
        self.jobs.wait_all(10.0)
        super().closeEvent(event)


def run_window(setup_window, args: Any = None) -> int:
    """Make the application and the window (``setup_window(win)`` loads or starts what
    the command asked for), run Qt's loop; with ``--quit-after S`` save ``--screenshot``
    and quit after S seconds (the checks outside the test suite use it)."""
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("imucap")
    win = MainWindow()
    win.show()
    setup_window(win)
    if getattr(args, "outdoor_skeleton", None):
        win.outdoor.set_skeleton(args.outdoor_skeleton)  # for this run; the saved choice stays
    if getattr(args, "view", None) == "outdoor":
        win.show_outdoor()
    quit_after = float(getattr(args, "quit_after", 0) or 0)
    if quit_after:
        def finish() -> None:
            stats = getattr(args, "window_stats", None)
            if stats:
                shown = win.outdoor.frames_shown + win.live_panel.frames_shown
                live = win.session
                hub = live.session.hub if live is not None else None
                win.cost.write(stats, shown, {
                    "pipeline": live.perf() if live is not None else None,
                    "outdoor": {"skeleton": win.outdoor.skeleton, "poses_not_redrawn": win.outdoor.frames_still},
                    "hub": None if hub is None else hub.wait_status(),
                    # why no pose was shown, when none was: the guided calibration's state
                    "calibration": live.session.guided.status() if live is not None else None})
            shot = getattr(args, "screenshot", None)
            if shot:
                Path(shot).parent.mkdir(parents=True, exist_ok=True)
                win.grab().save(str(shot))
            win.close()
            app.quit()

        QtCore.QTimer.singleShot(int(1000 * quit_after), finish)
    return int(app.exec())
