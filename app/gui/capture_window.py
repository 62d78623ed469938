"""The capture window: the calibration steps with their prompt and live stillness, the
live skeleton, each device's state, record, markers. Everything it shows is read from the
CaptureSession on a Qt timer; the session's threads do the work, so the window never
waits on a device or the model."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from PySide6 import QtCore, QtGui, QtWidgets

from app.capture.session import CaptureSession, SessionEvent
from app.gui.skeleton_view import SkeletonView
from inference.body.body import Body


class CaptureWindow(QtWidgets.QMainWindow):
    DEVICE_COLUMNS = ("device", "state", "packets", "lost", "reconnects", "battery")

    def __init__(self, session: CaptureSession, record_dir: Path | None = None, ui_hz: float = 30.0) -> None:
        super().__init__()
        self.session = session
        self.body = Body.from_height(session.setup.subject.height_m)
        self.record_dir = record_dir or session.setup.recordings
        self.setWindowTitle(f"imucap capture: {session.setup.subject.id}")
        self.resize(1200, 720)
        self.frames_shown = 0
        self._last_key: tuple[int, float] | None = None
        self._events: list[SessionEvent] = []

        split = QtWidgets.QSplitter()
        self.setCentralWidget(split)
        self.view = SkeletonView()
        split.addWidget(self.view)
        panel = QtWidgets.QWidget()
        side = QtWidgets.QVBoxLayout(panel)
        self.step_label = QtWidgets.QLabel("starting")
        self.step_label.setWordWrap(True)
        self.step_label.setStyleSheet("font-size: 15px")
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 100)
        self.quality_label = QtWidgets.QLabel("")
        self.quality_label.setWordWrap(True)
        self.perf_label = QtWidgets.QLabel("")
        redo = QtWidgets.QHBoxLayout()
        for step in session.guided.steps:
            b = QtWidgets.QPushButton(f"redo {step.name}")
            b.clicked.connect(lambda _=False, n=step.name: self.redo(n))
            redo.addWidget(b)
        side.addWidget(self.step_label)
        side.addWidget(self.progress)
        side.addLayout(redo)
        side.addWidget(self.quality_label)
        side.addWidget(self.perf_label)
        self.table = QtWidgets.QTableWidget(0, len(self.DEVICE_COLUMNS))
        self.table.setHorizontalHeaderLabels(self.DEVICE_COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        side.addWidget(self.table, 1)
        self.events_list = QtWidgets.QListWidget()
        side.addWidget(QtWidgets.QLabel("Events"))
        side.addWidget(self.events_list, 1)
        self.record_button = QtWidgets.QPushButton("Start recording (R)")
        self.record_button.setCheckable(True)
        self.record_button.toggled.connect(self._record_toggled)
        self.marker_button = QtWidgets.QPushButton("Marker (M)")
        self.marker_button.clicked.connect(lambda: self.session.add_marker(f"marker {self._marker_count() + 1}"))
        side.addWidget(self.record_button)
        side.addWidget(self.marker_button)
        QtGui.QShortcut(QtGui.QKeySequence("R"), self, activated=self.record_button.toggle)
        QtGui.QShortcut(QtGui.QKeySequence("M"), self, activated=self.marker_button.click)
        split.addWidget(panel)
        split.setSizes([800, 400])
        self.timer = QtCore.QTimer(self)
        self.timer.timeout.connect(self.update_view)
        self.timer.start(int(1000 / ui_hz))
        self.status_timer = QtCore.QTimer(self)
        self.status_timer.timeout.connect(self.update_status)
        self.status_timer.start(250)

    def _marker_count(self) -> int:
        return sum(e.kind == "marker" for e in self.session.events)

    def redo(self, step: str) -> None:
        s = self.session
        def on_pipeline(p) -> None:  # the guided calibration lives on the pipeline's thread
            p.calibration = None
            s.guided.redo(step)

        s.calibration = None
        if s.live is not None:
            s.live.call(on_pipeline)
        else:
            on_pipeline(s.pipeline)

    def update_view(self) -> None:
        lp = self.session.live.latest() if self.session.live is not None else None
        if lp is None or (lp.index, lp.t) == self._last_key:
            return
        self._last_key = (lp.index, lp.t)
        self.view.show_pose(lp.pose.joints, lp.pose.rot, lp.pose.contacts, self.body)
        self.frames_shown += 1

    def update_status(self) -> None:
        s = self.session
        s.poll()
        g = s.guided
        if s.calibration is None:
            f = g.feedback()
            self.step_label.setText(f"<b>Step {f.step_index + 1}/{f.steps}: {f.step}</b><br>{f.prompt}<br>"
                                    f"<i>{g.status().split(' -- ')[-1]}</i>")
            if f.phase == "countdown" and f.countdown is not None:
                self.progress.setValue(int(100 * (1 - f.countdown / max(g.countdown_s, 1e-6))))
            else:
                self.progress.setValue(int(100 * min(f.held / f.need, 1.0)) if f.need else 0)
        else:
            self.step_label.setText("<b>Calibrated</b>: live")
            self.progress.setValue(100)
            rep = g.report
            if rep is not None:
                self.quality_label.setText("<br>".join(rep.all_warnings()) or "calibration quality: ok")
        r = s.result()
        lat = r["latency_p50_ms"]
        self.perf_label.setText(f"{r['fps']:.1f} frames/s, latency p50 {'-' if lat is None else f'{lat:.0f} ms'}, "
                                f"dropped {r['pipeline'].get('dropped', 0)}")
        devs = r["devices"]
        self.table.setRowCount(len(devs))
        for row, (name, d) in enumerate(devs.items()):
            vals = (name, d.get("state") or "", str(d.get("packets", "")), str(d.get("lost", "")),
                    str(d.get("reconnects", "")), "-" if d.get("battery") is None else f"{d['battery']:.0f}%")
            for c, v in enumerate(vals):
                item = self.table.item(row, c)
                if item is None:
                    self.table.setItem(row, c, QtWidgets.QTableWidgetItem(v))
                elif item.text() != v:
                    item.setText(v)
        for ev in s.events[len(self._events):]:
            self.events_list.addItem(f"{time.strftime('%H:%M:%S')} {ev.kind}: {ev.detail}")
            self._events.append(ev)

    def _record_toggled(self, on: bool) -> None:
        if on:
            path = Path(self.record_dir) / time.strftime(f"{self.session.setup.subject.id}-%Y%m%d-%H%M%S.h5")
            try:
                self.session.start_recording(path)
            except OSError as exc:
                QtWidgets.QMessageBox.warning(self, "Cannot record", str(exc))
                self.record_button.setChecked(False)
                return
            self.record_button.setText(f"Stop recording ({path.name}) (R)")
        else:
            self.session.stop_recording()
            self.record_button.setText("Start recording (R)")

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt's name)
        self.timer.stop()
        self.status_timer.stop()
        super().closeEvent(event)


def run_capture_window(session: CaptureSession, args) -> int:
    """`imucap capture` with a display: start, show, run Qt's loop, stop (and a screenshot
    after ``--quit-after`` seconds for checks outside the test suite)."""
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    session.start()
    try:
        win = CaptureWindow(session)
        win.show()
        if getattr(args, "quit_after", 0):
            def finish() -> None:
                if getattr(args, "screenshot", None):
                    win.grab().save(str(args.screenshot))
                win.close()
                app.quit()

            QtCore.QTimer.singleShot(int(1000 * args.quit_after), finish)
        return int(app.exec())
    finally:
        session.stop()
