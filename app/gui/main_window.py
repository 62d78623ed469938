"""The demo's window: a 3D skeleton driven by the live pipeline, and a side panel for the
clinician (sensor status, model, recording, which sensors the reconstruction uses).

Threading: the pipeline runs on its own threads (``LivePipeline``); this window never
computes a pose. A QTimer (30 Hz) takes ``live.latest()`` (a reference swap, no lock) and
pushes it into the GL items with ``setData``; changes the user makes (sensor
configuration, recording) go to the pipeline thread through ``live.call``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from app.demo_session import DemoConfig, DemoSession
from app.gui.skeleton_view import SkeletonView
from app.pipeline import stride_text

PRESETS: dict[str, tuple[str, ...]] = {
    "paper 6 (pelvis, head, wrists, shanks)": ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank"),
    "3: pelvis + wrists": ("pelvis", "l_wrist", "r_wrist"),
    "2: shanks": ("l_shank", "r_shank"),
    "1: pelvis": ("pelvis",),
}


class DemoWindow(QtWidgets.QMainWindow):
    """Window over a started (or startable) DemoSession."""

    STATUS_COLUMNS = ("site", "protocol", "rate Hz", "packets", "gaps", "errors", "battery")

    def __init__(self, session: DemoSession, ui_hz: float = 30.0) -> None:
        super().__init__()
        self.session = session
        self.setWindowTitle("imucap demo: live reconstruction")
        self.resize(1200, 720)
        self.frames_shown = 0
        self._last_index: tuple[int, float] | None = None
        self.record_path: Path | None = None

        split = QtWidgets.QSplitter()
        self.setCentralWidget(split)

        # --- 3D view
        self.view = SkeletonView()
        split.addWidget(self.view)

        # --- side panel
        panel = QtWidgets.QWidget()
        side = QtWidgets.QVBoxLayout(panel)
        self.model_label = QtWidgets.QLabel()
        self.model_label.setWordWrap(True)
        self.status_label = QtWidgets.QLabel("starting")
        self.status_label.setWordWrap(True)
        self.perf_label = QtWidgets.QLabel("")
        # whether the walked distance comes from the shanks yet (a few strides after calibration)
        self.stride_label = QtWidgets.QLabel("")
        self.stride_label.setToolTip("The root path's scale from the shank sensors' own strides "
                                     "(inference/poser/stride.py): needs both shanks and a few steps")
        side.addWidget(self.model_label)
        if session.warning:
            warn = QtWidgets.QLabel("NO TRAINED MODEL: floor baseline")
            warn.setStyleSheet("color: #ff5050; font-weight: bold")
            warn.setToolTip(session.warning)
            side.addWidget(warn)
        side.addWidget(self.status_label)
        side.addWidget(self.perf_label)
        side.addWidget(self.stride_label)

        side.addWidget(QtWidgets.QLabel("Sensors"))
        self.table = QtWidgets.QTableWidget(0, len(self.STATUS_COLUMNS))
        self.table.setHorizontalHeaderLabels(self.STATUS_COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        side.addWidget(self.table, 1)

        # sensor configuration chooser: which of the suit's sensors the reconstruction uses
        box = QtWidgets.QGroupBox("Sensor configuration")
        bl = QtWidgets.QVBoxLayout(box)
        self.preset = QtWidgets.QComboBox()
        suit = tuple(session.cfg.sensors)
        self.preset.addItem("all sensors of the suit", suit)
        for name, sites in PRESETS.items():
            if set(sites) <= set(suit) and tuple(sites) != suit:
                self.preset.addItem(name, sites)
        self.preset.currentIndexChanged.connect(self._preset_chosen)
        bl.addWidget(self.preset)
        self.site_checks: dict[str, QtWidgets.QCheckBox] = {}
        checks = QtWidgets.QGridLayout()
        for k, s in enumerate(suit):
            cb = QtWidgets.QCheckBox(s)
            cb.setChecked(True)
            self.site_checks[s] = cb
            checks.addWidget(cb, k // 2, k % 2)
        bl.addLayout(checks)
        self.insoles_check = QtWidgets.QCheckBox("insoles (contacts)")
        self.insoles_check.setChecked(session.cfg.insoles)
        self.insoles_check.setEnabled(session.cfg.insoles)
        bl.addWidget(self.insoles_check)
        self.apply_button = QtWidgets.QPushButton("Apply configuration")
        self.apply_button.clicked.connect(self.apply_configuration)
        bl.addWidget(self.apply_button)
        side.addWidget(box)

        self.record_button = QtWidgets.QPushButton("Start recording")
        self.record_button.setCheckable(True)
        self.record_button.toggled.connect(self._record_toggled)
        side.addWidget(self.record_button)
        split.addWidget(panel)
        split.setSizes([820, 380])

        self._refresh_labels()
        self.timer = QtCore.QTimer(self)
        self.timer.timeout.connect(self.update_view)
        self.timer.start(int(1000 / ui_hz))
        self.status_timer = QtCore.QTimer(self)
        self.status_timer.timeout.connect(self.update_status)
        self.status_timer.start(500)

    # ------------------------------------------------------------------ updates
    def _refresh_labels(self) -> None:
        s = self.session
        self.model_label.setText(f"<b>Model</b>: {s.model_label}<br><b>Steps</b>: {s.steps_count()}"
                                 f"<br><b>Protocol</b>: {s.cfg.protocol}")

    def update_view(self) -> None:
        """Timer slot: newest pose -> GL items (only when it changed)."""
        live = self.session.live
        lp = live.latest() if live is not None else None
        if lp is None:
            return
        key = (lp.index, lp.t)
        if key == self._last_index:
            return
        self._last_index = key
        self.view.show_pose(lp.pose.joints, lp.pose.rot, lp.pose.contacts, self.session.truth.body)
        self.frames_shown += 1

    def update_status(self) -> None:
        s = self.session
        self.status_label.setText(f"<b>Status</b>: {s.pipeline.status}")
        if s.live is not None:
            st = s.live.stats()
            lat, step = st["latency_p50_ms"], st["step_p50_ms"]
            self.perf_label.setText(
                f"frames {st['poses']}, dropped {st['dropped']}, latency p50 "
                f"{'-' if lat is None else f'{lat:.0f} ms'}, step p50 "
                f"{'-' if step is None else f'{step:.1f} ms'}")
        self.stride_label.setText(f"<b>Stride from shanks</b>: {stride_text(s.pipeline.stride_status())}")
        status = s.sensor_status()
        self.table.setRowCount(len(status))
        for r, (site, d) in enumerate(status.items()):
            vals = (site, d["protocol"], f"{d['rate_hz']:.0f}", str(d["packets"]), str(d["gaps"]),
                    str(d["errors"]), "-" if d["battery"] is None else f"{d['battery']:.0f}%")
            for c, v in enumerate(vals):
                item = self.table.item(r, c)
                if item is None:
                    self.table.setItem(r, c, QtWidgets.QTableWidgetItem(v))
                elif item.text() != v:
                    item.setText(v)

    # ------------------------------------------------------------------ actions
    def _preset_chosen(self, i: int) -> None:
        sites = set(self.preset.itemData(i) or ())
        for s, cb in self.site_checks.items():
            cb.setChecked(s in sites)
        self.apply_configuration()

    def chosen_sites(self) -> tuple[str, ...]:
        return tuple(s for s, cb in self.site_checks.items() if cb.isChecked())

    def apply_configuration(self) -> None:
        sites, insoles = self.chosen_sites(), self.insoles_check.isChecked()
        if self.session.live is not None:
            self.session.live.call(lambda p: p.set_active_sites(sites, insoles))
        else:
            self.session.pipeline.set_active_sites(sites, insoles)

    def _record_toggled(self, on: bool) -> None:
        if on:
            path = self.record_path or Path("recordings") / time.strftime("session-%Y%m%d-%H%M%S.h5")
            self.record_path = Path(path)
            self.session.start_recording(self.record_path)
            self.record_button.setText(f"Stop recording ({self.record_path.name})")
        else:
            self.session.stop_recording()
            self.record_button.setText("Start recording")

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt's name)
        self.timer.stop()
        self.status_timer.stop()
        super().closeEvent(event)


def run_gui(cfg: DemoConfig) -> int:
    """`imucap demo` with the window: start the session, show, run Qt's loop, stop."""
    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    session = DemoSession(cfg)
    if session.warning:
        print(session.warning, file=sys.stderr)
    session.start()
    try:
        win = DemoWindow(session)
        win.show()
        return int(app.exec())
    finally:
        session.stop()
