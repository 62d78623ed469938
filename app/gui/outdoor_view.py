"""Outdoor: the live view for a runner glancing at a laptop from a few metres, in the sun.

Why a view of its own: the Live tab is made for someone at the desk (signals, checkboxes,
an event list). Outdoors the screen is far, small against the sky and washed out, so this
one shows only what a glance can take in: the skeleton, three numbers in large type on
black (cadence, knee flexion range per side, left/right asymmetry), a battery and signal
bar per sensor, and one large record button. High contrast: white and yellow on black;
a number that needs attention turns orange.

It draws what the window hands it (``show_pose`` at the view timer, ``show_numbers`` and
``show_devices`` a few times a second); the numbers come from ``app.live.gait.GaitSink``.

The skeleton is drawn flat by default (``SKELETONS``: "2d", side on, the camera turning with
the runner so the legs are always seen from the side), with thick lines for a glance from a
distance; "3d" is the desk view's GL skeleton. On battery the drawing is the athlete's run
time: the flat view costs a fraction of GL's (no GL pipeline; under software GL most of
the window's CPU, docs/window.md), and nothing is redrawn for a pose that did not move.
"""

from __future__ import annotations

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.gui import views
from app.gui.colours import segment_colours
from app.live import LivePose
from inference.body.body import Body
from inference.metrics.gait import GaitNumbers

BG = "#000000"
FG = "#ffffff"
ACCENT = "#ffd400"  # yellow: the most legible colour on black in daylight
WARN = "#ff8c00"
GOOD = "#22dd44"
BAD = "#ff3030"
ASYMMETRY_WARN_PCT = 10.0  # past this the left/right difference of knee range is worth a look
STALE_S = 1.0  # a sensor silent this long shows no signal
SKELETONS = ("2d", "3d")
STILL_M = 0.002  # a pose whose joints all moved less than this since the one drawn is not drawn again


def _label(text: str, px: int, colour: str = FG, bold: bool = False) -> QtWidgets.QLabel:
    lab = QtWidgets.QLabel(text)
    lab.setStyleSheet(f"color: {colour}; font-size: {px}px; {'font-weight: bold;' if bold else ''}")
    return lab


class _Number(QtWidgets.QWidget):
    """A caption over a large value and its unit."""

    def __init__(self, caption: str, unit: str) -> None:
        super().__init__()
        lay = QtWidgets.QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 8)
        lay.setSpacing(0)
        self.caption = _label(caption, 26, FG, bold=True)
        row = QtWidgets.QHBoxLayout()
        self.value = _label("--", 84, ACCENT, bold=True)
        self._colour = ACCENT
        self.unit = _label(unit, 30, FG)
        row.addWidget(self.value)
        row.addWidget(self.unit, 0, QtCore.Qt.AlignmentFlag.AlignBottom)
        row.addStretch(1)
        lay.addWidget(self.caption)
        lay.addLayout(row)

    def set(self, text: str, colour: str = ACCENT) -> None:
        # each change repaints (a style sheet also re-polishes the widget): only what changed
        if self.value.text() != text:
            self.value.setText(text)
        if colour != self._colour:
            self._colour = colour
            self.value.setStyleSheet(f"color: {colour}; font-size: 84px; font-weight: bold;")


class _SensorBars(QtWidgets.QWidget):
    """Per sensor: its name, a battery bar and a signal bar (packets arriving, none lost)."""

    def __init__(self) -> None:
        super().__init__()
        self.grid = QtWidgets.QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setHorizontalSpacing(10)
        self.rows: dict[str, tuple[QtWidgets.QLabel, QtWidgets.QProgressBar, QtWidgets.QProgressBar]] = {}
        self._silent: dict[str, bool] = {}

    @staticmethod
    def _bar(colour: str) -> QtWidgets.QProgressBar:
        bar = QtWidgets.QProgressBar()
        bar.setRange(0, 100)
        bar.setTextVisible(False)
        bar.setFixedHeight(16)
        bar.setStyleSheet(f"QProgressBar {{ background: #333; border: 1px solid #888; }}"
                          f"QProgressBar::chunk {{ background: {colour}; }}")
        return bar

    def show_rows(self, rows) -> None:
        for r in rows:
            if r.name not in self.rows:
                k = len(self.rows)
                name = _label(r.name, 20, FG, bold=True)
                batt, sig = self._bar(ACCENT), self._bar(GOOD)
                self.grid.addWidget(name, k, 0)
                self.grid.addWidget(_label("batt", 16), k, 1)
                self.grid.addWidget(batt, k, 2)
                self.grid.addWidget(_label("signal", 16), k, 3)
                self.grid.addWidget(sig, k, 4)
                self.rows[r.name] = (name, batt, sig)
            name, batt, sig = self.rows[r.name]
            # a progress bar's setValue repaints at once, and with it whatever else waits to be
            # drawn in the window: only what changed
            level = int(round(r.battery)) if r.battery is not None else 0
            if batt.value() != level:
                batt.setValue(level)
            if batt.isEnabled() != (r.battery is not None):
                batt.setEnabled(r.battery is not None)
            silent = r.last_seen_s is None or r.last_seen_s > STALE_S or r.state != "ok"
            signal = max(0, min(100, 0 if silent else int(round(100.0 - (r.loss_pct or 0.0)))))
            if sig.value() != signal:
                sig.setValue(signal)
            if self._silent.get(r.name) != silent:
                self._silent[r.name] = silent
                name.setStyleSheet(f"color: {BAD if silent else FG}; font-size: 20px; font-weight: bold;")


class OutdoorView(QtWidgets.QWidget):
    recordToggled = QtCore.Signal(bool)
    skeletonChosen = QtCore.Signal(str)  # "2d" or "3d", when the user switches

    def __init__(self, parent: QtWidgets.QWidget | None = None, skeleton: str = "2d") -> None:
        super().__init__(parent)
        self.setObjectName("outdoor")
        self.setAttribute(QtCore.Qt.WidgetAttribute.WA_StyledBackground, True)
        self.setStyleSheet(f"#outdoor {{ background: {BG}; }} QLabel {{ background: {BG}; }}")
        self._last_key: tuple[int, float] | None = None
        self._drawn: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # joints, contacts, colours
        self.frames_shown = 0
        self.frames_still = 0  # poses not drawn because nothing moved
        lay = QtWidgets.QHBoxLayout(self)
        left = QtWidgets.QVBoxLayout()
        self.skeleton_button = QtWidgets.QPushButton()
        self.skeleton_button.setStyleSheet(f"QPushButton {{ background: #222; color: {FG}; font-size: 18px; "
                                           f"border: 1px solid #888; padding: 4px 10px; }}")
        self.skeleton_button.clicked.connect(self._toggle_skeleton)
        left.addWidget(self.skeleton_button, 0, QtCore.Qt.AlignmentFlag.AlignLeft)
        self.view_box = left
        lay.addLayout(left, 3)
        self.skeleton = ""
        self.view: QtWidgets.QWidget | None = None
        self.set_skeleton(skeleton)

        right = QtWidgets.QVBoxLayout()
        self.record_button = QtWidgets.QPushButton("● REC")
        self.record_button.setCheckable(True)
        self.record_button.setEnabled(False)
        self.record_button.setMinimumHeight(90)
        self.record_button.toggled.connect(self._record_toggled)
        self._style_record(False)
        self.record_label = _label("", 22, FG)
        right.addWidget(self.record_button)
        right.addWidget(self.record_label)
        self.cadence = _Number("CADENCE", "steps/min")
        self.knees = _Number("KNEE RANGE  L / R", "deg")
        self.asymmetry = _Number("ASYMMETRY", "%")
        for w in (self.cadence, self.knees, self.asymmetry):
            right.addWidget(w)
        right.addStretch(1)
        self.sensors = _SensorBars()
        right.addWidget(self.sensors)
        lay.addLayout(right, 2)

    # ------------------------------------------------------------------ the skeleton
    def set_skeleton(self, kind: str) -> None:
        """Draw with the flat side-on skeleton ("2d", QPainter) or the desk view's ("3d": GL, or
        the flat view where GL cannot run)."""
        if kind not in SKELETONS:
            raise ValueError(f"outdoor skeleton {kind!r}: choose one of {', '.join(SKELETONS)}")
        if kind == self.skeleton:
            return
        if kind == "3d":
            view = views.make_skeleton_view(self)
        else:
            from app.gui.view2d import Skeleton2DView

            view = Skeleton2DView(self)
            view.set_side_on(True)
            view.line_px, view.joint_px, view.grid_alpha = 9.0, 6.0, 90
        view.setBackgroundColor(BG)  # both views take "#rrggbb" (the GL one through pyqtgraph's mkColor)
        if self.view is not None:
            self.view_box.removeWidget(self.view)
            self.view.deleteLater()
        self.view_box.addWidget(view, 1)
        self.view, self.skeleton, self._drawn, self._last_key = view, kind, None, None
        self.skeleton_button.setText("3D view" if kind == "2d" else "side view")

    def _toggle_skeleton(self) -> None:
        self.set_skeleton("3d" if self.skeleton == "2d" else "2d")
        self.skeletonChosen.emit(self.skeleton)

    # ------------------------------------------------------------------ drawing
    def show_pose(self, lp: LivePose | None, body: Body) -> bool:
        if lp is None or (lp.index, lp.t) == self._last_key:
            return False
        self._last_key = (lp.index, lp.t)
        colours = segment_colours(lp.observed_sites, getattr(lp.pose, "spread_deg", None))
        joints = np.asarray(lp.pose.joints, dtype=np.float64)
        contacts = np.asarray(lp.pose.contacts, dtype=bool)
        if self._drawn is not None and self._still(joints, contacts, colours):
            self.frames_still += 1  # a body standing still: the screen already shows it
            return False
        self._drawn = (joints, contacts, colours)
        self.view.set_segment_colours(colours)
        self.view.show_pose(joints, lp.pose.rot, contacts, body)
        self.frames_shown += 1
        return True

    def _still(self, joints: np.ndarray, contacts: np.ndarray, colours: np.ndarray) -> bool:
        j, c, col = self._drawn
        return (j.shape == joints.shape and float(np.abs(joints - j).max()) < STILL_M
                and np.array_equal(c, contacts) and np.array_equal(col, colours))

    def show_numbers(self, n: GaitNumbers) -> None:
        self.cadence.set("--" if n.cadence_spm is None else f"{n.cadence_spm:.0f}")
        left, right = n.knee_range_deg
        self.knees.set("--" if left is None or right is None else f"{left:.0f} / {right:.0f}")
        if n.asymmetry_pct is None:
            self.asymmetry.set("--")
        else:
            self.asymmetry.set(f"{n.asymmetry_pct:.0f}", WARN if n.asymmetry_pct > ASYMMETRY_WARN_PCT else ACCENT)

    def show_devices(self, rows) -> None:
        self.sensors.show_rows(rows)

    # ------------------------------------------------------------------ recording
    def _style_record(self, on: bool) -> None:
        colour = BAD if on else "#7a0000"
        self.record_button.setText("■ STOP" if on else "● REC")
        self.record_button.setStyleSheet(f"QPushButton {{ background: {colour}; color: {FG}; font-size: 40px; "
                                         f"font-weight: bold; border: 3px solid {FG}; border-radius: 12px; }}"
                                         f"QPushButton:disabled {{ background: #333; color: #888; }}")

    def _record_toggled(self, on: bool) -> None:
        self._style_record(on)
        self.recordToggled.emit(on)

    def set_recording(self, on: bool, text: str) -> None:
        """Reflect the session's state without re-emitting ``recordToggled`` (a few times a
        second while recording: the button restyled only when the state changes)."""
        if self.record_button.isChecked() != on:
            self.record_button.blockSignals(True)
            self.record_button.setChecked(on)
            self.record_button.blockSignals(False)
            self._style_record(on)
        if self.record_label.text() != text:
            self.record_label.setText(text)

    def set_record_enabled(self, on: bool) -> None:
        self.record_button.setEnabled(on)



