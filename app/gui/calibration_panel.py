"""The calibration wizard: the step's picture and prompt, the countdown, how still each
sensor is, the quality report with its warnings, and redo per step.

Why live stillness bars: a step that will not complete is almost always one sensor
(a loose strap, an arm that drifts); the bar that stays red names it while the person is
still standing there, instead of a timeout message thirty seconds later.
"""

from __future__ import annotations

from PySide6 import QtCore, QtWidgets

from app.gui.pose_pictures import PosePicture
from app.gui.widgets import SpeedBars
from calibration.guided import PROTOCOLS, GuidedFeedback
from calibration.quality import QualityReport

QUALITY_COLUMNS = ("sensor", "still", "heading ±", "swing", "result")


class CalibrationPanel(QtWidgets.QWidget):
    redoRequested = QtCore.Signal(str)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.protocol = "walk"
        self.still_dps, self.moved_dps = 20.0, 35.0
        self._report_shown: QualityReport | None = None
        lay = QtWidgets.QHBoxLayout(self)

        left = QtWidgets.QVBoxLayout()
        self.picture = PosePicture()
        left.addWidget(self.picture, 3)
        self.steps_box = QtWidgets.QGroupBox("Steps")
        self.steps_layout = QtWidgets.QGridLayout(self.steps_box)
        self.step_labels: dict[str, QtWidgets.QLabel] = {}
        self.redo_buttons: dict[str, QtWidgets.QPushButton] = {}
        left.addWidget(self.steps_box)
        lay.addLayout(left, 2)

        right = QtWidgets.QVBoxLayout()
        self.step_title = QtWidgets.QLabel("No capture running")
        self.step_title.setStyleSheet("font-size: 18px; font-weight: bold")
        self.prompt = QtWidgets.QLabel("Set up the subject and the devices, then press Start capture.")
        self.prompt.setWordWrap(True)
        self.prompt.setStyleSheet("font-size: 15px")
        self.countdown = QtWidgets.QLabel("")
        self.countdown.setStyleSheet("font-size: 30px; font-weight: bold; color: #2a62c9")
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 100)
        self.progress.setFormat("%p%")
        self.message = QtWidgets.QLabel("")
        self.message.setWordWrap(True)
        self.message.setStyleSheet("color: #b03030; font-weight: bold")
        right.addWidget(self.step_title)
        right.addWidget(self.prompt)
        right.addWidget(self.countdown)
        right.addWidget(self.progress)
        right.addWidget(self.message)
        right.addWidget(QtWidgets.QLabel("<b>Stillness</b> (angular speed of each sensor; dashed: the limits)"))
        self.speeds = SpeedBars()
        right.addWidget(self.speeds)
        right.addWidget(QtWidgets.QLabel("<b>Quality report</b>"))
        self.quality = QtWidgets.QTableWidget(0, len(QUALITY_COLUMNS))
        self.quality.setHorizontalHeaderLabels(QUALITY_COLUMNS)
        self.quality.verticalHeader().setVisible(False)
        self.quality.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.quality.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Stretch)
        right.addWidget(self.quality, 1)
        self.warnings = QtWidgets.QLabel("")
        self.warnings.setWordWrap(True)
        right.addWidget(self.warnings)
        lay.addLayout(right, 3)
        self.set_protocol("walk")

    def set_protocol(self, protocol: str, still_dps: float = 20.0, moved_dps: float = 35.0) -> None:
        """Build one row per step with its redo button."""
        self.protocol, self.still_dps, self.moved_dps = protocol, still_dps, moved_dps
        for w in (*self.step_labels.values(), *self.redo_buttons.values()):
            w.deleteLater()
        self.step_labels, self.redo_buttons = {}, {}
        for k, step in enumerate(PROTOCOLS[protocol]):
            label = QtWidgets.QLabel(f"{k + 1}. {step.name}")
            button = QtWidgets.QPushButton(f"Redo {step.name}")
            button.clicked.connect(lambda _=False, n=step.name: self.redoRequested.emit(n))
            self.steps_layout.addWidget(label, k, 0)
            self.steps_layout.addWidget(button, k, 1)
            self.step_labels[step.name], self.redo_buttons[step.name] = label, button
        self.picture.set_pose(PROTOCOLS[protocol][0].pose)

    # ------------------------------------------------------------------ updates from the session
    def show_feedback(self, f: GuidedFeedback, phase_error: str | None, countdown_s: float) -> None:
        steps = PROTOCOLS[self.protocol]
        step = steps[min(f.step_index, len(steps) - 1)]
        self.picture.set_pose(step.pose)
        self.step_title.setText(f"Step {f.step_index + 1} of {f.steps}: {f.step}")
        self.prompt.setText(f.prompt)
        for k, s in enumerate(steps):
            mark = "✓" if k < f.step_index else ("▶" if k == f.step_index else "·")
            self.step_labels[s.name].setText(f"{mark} {k + 1}. {s.name}")
        if f.phase == "countdown" and f.countdown is not None:
            self.countdown.setText(f"starting in {f.countdown:.0f}")
            self.progress.setValue(int(100 * (1 - f.countdown / max(countdown_s, 1e-6))))
        else:
            words = {"waiting_still": "waiting for everyone to be still", "holding": "hold still…",
                     "waiting_move": "waiting for the walk to start", "moving": "walking…",
                     "settling": "stand still…", "failed": "failed", "done": "done"}
            self.countdown.setText(words.get(f.phase, f.phase.replace("_", " ")))
            self.progress.setValue(int(100 * min(f.held / f.need, 1.0)) if f.need else 0)
        self.message.setText(phase_error or f.message or (f"moving: {', '.join(f.moving)}" if f.moving else ""))
        self.speeds.set_speeds(f.speeds, self.still_dps, self.moved_dps)

    def show_done(self, report: QualityReport | None) -> None:
        self.step_title.setText("Calibrated")
        self.prompt.setText("The live view is running. Redo a step if the report asks for it.")
        self.countdown.setText("✓ done")
        self.progress.setValue(100)
        for k, s in enumerate(PROTOCOLS[self.protocol]):
            self.step_labels[s.name].setText(f"✓ {k + 1}. {s.name}")
        self.message.setText("")
        if report is not None and report is not self._report_shown:
            self.show_report(report)

    def show_report(self, report: QualityReport) -> None:
        self._report_shown = report
        rows = list(report.sensors.items())
        self.quality.setRowCount(len(rows))

        def deg(v: float | None) -> str:
            return "–" if v is None else f"{v:.1f}°"

        for r, (site, q) in enumerate(rows):
            vals = (site, deg(q.still_rotation_deg), deg(q.heading_spread_deg), deg(q.swing_deg),
                    "ok" if not q.warnings else "CHECK: " + "; ".join(q.warnings))
            for c, v in enumerate(vals):
                item = QtWidgets.QTableWidgetItem(v)
                if c == 4:
                    item.setToolTip(v)
                self.quality.setItem(r, c, item)
        warnings = report.all_warnings()
        text = "<br>".join(f"⚠ {w}" for w in warnings) if warnings else "<span style='color:#208040'>" \
                                                                          "every sensor passed its checks</span>"
        if report.redo:
            text += f"<br><b>worth redoing:</b> {', '.join(report.redo)}"
        self.warnings.setText(text)

    def set_redo_enabled(self, on: bool) -> None:
        for b in self.redo_buttons.values():
            b.setEnabled(on)

    def show_idle(self, text: str = "No capture running") -> None:
        self.step_title.setText(text)
        self.countdown.setText("")
        self.progress.setValue(0)
        self.speeds.set_speeds({}, self.still_dps, self.moved_dps)

