"""Live: the skeleton, the root's trail, the chosen sensors' signals, and recording with
markers and notes.

Why colours and a trail on the skeleton: an athlete watching themselves wants the motion;
a clinician also needs to know which of it was measured and which the model filled in,
and whether the walked path drifts. The plots are the raw signals of chosen sensors, the
first place to look when a segment moves wrong.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from app.gui import views
from app.gui.colours import segment_colours
from app.gui.signal_tap import QUANTITIES, SignalTap
from app.gui.widgets import Legend
from app.live import LivePose
from inference.body.body import Body

PLOT_COLOURS = ("#3b82f6", "#ef4444", "#10b981", "#f59e0b", "#8b5cf6", "#ec4899", "#14b8a6", "#64748b")
TRAIL_STEP_M = 0.01
MAX_EVENTS = 500  # the list keeps the latest; the recording keeps them all


class LivePanel(QtWidgets.QWidget):
    recordToggled = QtCore.Signal(bool)
    markerRequested = QtCore.Signal(str)
    noteRequested = QtCore.Signal(str)
    activeSitesChosen = QtCore.Signal(tuple, bool)  # the worn sensors the reconstruction uses, insoles

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.tap: SignalTap | None = None
        self.frames_shown = 0
        self._last_key: tuple[int, float] | None = None
        self._trail: list[np.ndarray] = []
        self.has_spread = False
        self._recording_shown: bool | None = None  # the state the record label is styled for
        lay = QtWidgets.QHBoxLayout(self)

        # --- the view and its camera
        left = QtWidgets.QVBoxLayout()
        self.view = views.make_skeleton_view(None)  # put in by views.add_view below
        bar = QtWidgets.QHBoxLayout()
        self.follow = QtWidgets.QCheckBox("Follow")
        self.follow.setChecked(True)
        self.follow.toggled.connect(self._follow_toggled)
        bar.addWidget(self.follow)
        for name in ("front", "side", "top", "free"):
            b = QtWidgets.QPushButton(name.capitalize())
            b.clicked.connect(lambda _=False, n=name: self.view.set_view(n))
            bar.addWidget(b)
        self.trail_box = QtWidgets.QCheckBox("Trail")
        self.trail_box.setChecked(True)
        self.trail_box.toggled.connect(lambda _on: self._show_trail())
        clear = QtWidgets.QPushButton("Clear trail")
        clear.clicked.connect(self.clear_trail)
        bar.addWidget(self.trail_box)
        bar.addWidget(clear)
        bar.addStretch(1)
        self.legend = Legend()
        left.addLayout(bar)
        if not getattr(self.view, "is_gl", False):
            note = QtWidgets.QLabel(f"2D view: {views.GL_PROBLEM or 'OpenGL is not available'}")
            note.setStyleSheet("color: #a05000")
            left.addWidget(note)
        views.add_view(self, left, self.view, 1)
        left.addWidget(self.legend)
        lay.addLayout(left, 3)

        # --- signals, recording, events
        right = QtWidgets.QVBoxLayout()
        box = QtWidgets.QGroupBox("Sensor signals")
        bl = QtWidgets.QVBoxLayout(box)
        self.quantity = QtWidgets.QComboBox()
        self.quantity.addItems(list(QUANTITIES))
        self.site_list = QtWidgets.QListWidget()
        self.site_list.setFixedHeight(52)  # two rows of sites; the plot gets the rest
        self.site_list.setFlow(QtWidgets.QListView.Flow.LeftToRight)
        self.site_list.setWrapping(True)
        self.plot = pg.PlotWidget(background="w")
        self.plot.setMinimumHeight(170)
        self.plot.showGrid(x=True, y=True, alpha=0.3)
        self.plot.setLabel("bottom", "s")
        self.plot.addLegend(offset=(5, 5))
        self.curves: dict[tuple[str, int], pg.PlotDataItem] = {}
        bl.addWidget(self.quantity)
        bl.addWidget(self.site_list)
        bl.addWidget(self.plot, 1)
        right.addWidget(box, 2)

        # which of the worn sensors feed the reconstruction, changed live: "what would three give?"
        box = QtWidgets.QGroupBox("Reconstruct from")
        bl = QtWidgets.QVBoxLayout(box)
        self.active_grid = QtWidgets.QGridLayout()
        self.active_checks: dict[str, QtWidgets.QCheckBox] = {}
        self.active_insoles = QtWidgets.QCheckBox("insoles")
        self.apply_active = QtWidgets.QPushButton("Apply")
        self.apply_active.clicked.connect(self._apply_active)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.active_insoles)
        row.addStretch(1)
        row.addWidget(self.apply_active)
        bl.addLayout(self.active_grid)
        bl.addLayout(row)
        right.addWidget(box)

        box = QtWidgets.QGroupBox("Recording")
        grid = QtWidgets.QGridLayout(box)
        self.record_button = QtWidgets.QPushButton("● Record (R)")
        self.record_button.setCheckable(True)
        self.record_button.setEnabled(False)
        self.record_button.toggled.connect(self._record_toggled)
        self.record_label = QtWidgets.QLabel("not recording")
        self.marker_edit = QtWidgets.QLineEdit()
        self.marker_edit.setPlaceholderText("marker label (optional)")
        self.marker_edit.returnPressed.connect(self.request_marker)
        self.marker_button = QtWidgets.QPushButton("Marker (M)")
        self.marker_button.clicked.connect(self.request_marker)
        self.note_edit = QtWidgets.QLineEdit()
        self.note_edit.setPlaceholderText("note (e.g. 'patient tired, short break')")
        self.note_edit.returnPressed.connect(self._request_note)
        note_button = QtWidgets.QPushButton("Add note")
        note_button.clicked.connect(self._request_note)
        grid.addWidget(self.record_button, 0, 0)
        grid.addWidget(self.record_label, 0, 1)
        grid.addWidget(self.marker_edit, 1, 0)
        grid.addWidget(self.marker_button, 1, 1)
        grid.addWidget(self.note_edit, 2, 0)
        grid.addWidget(note_button, 2, 1)
        right.addWidget(box)
        right.addWidget(QtWidgets.QLabel("<b>Events</b>"))
        self.events = QtWidgets.QListWidget()
        self.events.setMinimumHeight(90)
        right.addWidget(self.events, 1)
        lay.addLayout(right, 2)
        self.marker_count = 0

    # ------------------------------------------------------------------ session
    def attach(self, tap: SignalTap | None, sites: tuple[str, ...], insoles: bool = False) -> None:
        self.tap = tap
        self.site_list.clear()
        for k, s in enumerate(sites):
            item = QtWidgets.QListWidgetItem(s)
            item.setFlags(item.flags() | QtCore.Qt.ItemFlag.ItemIsUserCheckable)
            item.setCheckState(QtCore.Qt.CheckState.Checked if k < 2 else QtCore.Qt.CheckState.Unchecked)
            self.site_list.addItem(item)
        for cb in self.active_checks.values():
            cb.deleteLater()
        self.active_checks = {}
        for k, site in enumerate(sites):
            cb = QtWidgets.QCheckBox(site)
            cb.setChecked(True)
            self.active_grid.addWidget(cb, k // 4, k % 4)
            self.active_checks[site] = cb
        self.active_insoles.setEnabled(insoles)
        self.active_insoles.setChecked(insoles)
        self.clear_trail()
        self.frames_shown = 0
        self._last_key = None

    def chosen_plot_sites(self) -> list[str]:
        return [self.site_list.item(i).text() for i in range(self.site_list.count())
                if self.site_list.item(i).checkState() == QtCore.Qt.CheckState.Checked]

    def set_plot_sites(self, sites: list[str]) -> None:
        for i in range(self.site_list.count()):
            item = self.site_list.item(i)
            item.setCheckState(QtCore.Qt.CheckState.Checked if item.text() in sites else QtCore.Qt.CheckState.Unchecked)

    # ------------------------------------------------------------------ drawing (GUI timers)
    def show_pose(self, lp: LivePose | None, body: Body) -> bool:
        """Draw ``lp`` if it is new; True when something was drawn."""
        if lp is None or (lp.index, lp.t) == self._last_key:
            return False
        self._last_key = (lp.index, lp.t)
        spread = getattr(lp.pose, "spread_deg", None)
        self.has_spread = spread is not None
        self.legend.set_spread(self.has_spread)
        self.view.set_segment_colours(segment_colours(lp.observed_sites, spread))
        self.view.show_pose(lp.pose.joints, lp.pose.rot, lp.pose.contacts, body)
        root = np.asarray(lp.pose.joints[0], float)
        if not self._trail or np.linalg.norm(root[:2] - self._trail[-1][:2]) > TRAIL_STEP_M:
            self._trail.append(root)
            if len(self._trail) > 4000:
                del self._trail[:1000]
            self._show_trail()
        self.frames_shown += 1
        return True

    def update_plots(self) -> None:
        if self.tap is None:
            return
        quantity = self.quantity.currentText()
        shape = QUANTITIES[quantity][1]
        wanted: set[tuple[str, int]] = set()
        for k, site in enumerate(self.chosen_plot_sites()):
            t, v = self.tap.series(site, quantity)
            columns = [v] if shape == "norm" else [v[:, c] if len(v) else v for c in range(3)]
            for c, y in enumerate(columns):
                key = (site, c)
                wanted.add(key)
                curve = self.curves.get(key)
                if curve is None:
                    name = site if shape == "norm" else f"{site} {'xyz'[c]}"
                    pen = pg.mkPen(PLOT_COLOURS[(3 * k + c) % len(PLOT_COLOURS)], width=1.5)
                    curve = self.curves[key] = self.plot.plot(name=name, pen=pen, connect="finite")
                curve.setData(t, y if len(y) else np.zeros(0))
        for key in [k for k in self.curves if k not in wanted]:
            self.plot.removeItem(self.curves.pop(key))

    def _show_trail(self) -> None:
        self.view.set_trail(np.array(self._trail) if self.trail_box.isChecked() and self._trail else np.zeros((0, 3)))

    def clear_trail(self) -> None:
        self._trail = []
        self._show_trail()

    def _follow_toggled(self, on: bool) -> None:
        self.view.follow = on

    def choose_active(self, sites: tuple[str, ...] | list[str], insoles: bool | None = None) -> None:
        for s, cb in self.active_checks.items():
            cb.setChecked(s in sites)
        if insoles is not None and self.active_insoles.isEnabled():
            self.active_insoles.setChecked(insoles)
        self._apply_active()

    def _apply_active(self) -> None:
        sites = tuple(s for s, cb in self.active_checks.items() if cb.isChecked())
        self.activeSitesChosen.emit(sites, self.active_insoles.isChecked())

    # ------------------------------------------------------------------ recording widgets
    def _record_toggled(self, on: bool) -> None:
        self.record_button.setText("■ Stop recording (R)" if on else "● Record (R)")
        self.recordToggled.emit(on)

    def set_recording(self, on: bool, text: str) -> None:
        """Reflect the session's state without re-emitting ``recordToggled`` (a few times a second
        while recording: a style sheet re-polishes its widget, so it is set only on a change)."""
        if self.record_button.isChecked() != on or self._recording_shown is None:
            self.record_button.blockSignals(True)
            self.record_button.setChecked(on)
            self.record_button.setText("■ Stop recording (R)" if on else "● Record (R)")
            self.record_button.blockSignals(False)
        if self._recording_shown != on:
            self._recording_shown = on
            self.record_label.setStyleSheet("color: #c02020; font-weight: bold" if on else "")
        if self.record_label.text() != text:
            self.record_label.setText(text)

    def request_marker(self) -> None:
        self.marker_count += 1
        label = self.marker_edit.text().strip() or f"marker {self.marker_count}"
        self.marker_edit.clear()
        self.markerRequested.emit(label)

    def _request_note(self) -> None:
        text = self.note_edit.text().strip()
        if text:
            self.note_edit.clear()
            self.noteRequested.emit(text)

    def add_event(self, text: str, alarm: bool = False) -> None:
        item = QtWidgets.QListWidgetItem(text)
        if alarm:
            item.setForeground(QtCore.Qt.GlobalColor.red)
        self.events.addItem(item)
        while self.events.count() > MAX_EVENTS:
            self.events.takeItem(0)
        self.events.scrollToBottom()
