"""Recordings: the sessions in the setup's recordings folder, newest first, with subject,
date, length and sensors, to open in the replay or to make a gait report of (``app.report``:
``<recording>_report.html`` beside it, written on a thread; a link to it appears when done).

Why read only attributes and two time stamps: a folder holds hundreds of sessions of
minutes each; reading each one whole to list it would take the folder's size in I/O,
while the header and the first and last raw time take a few small reads per file.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.gui.workers import Jobs

COLUMNS = ("file", "subject", "date", "length", "sensors", "markers", "model")


@dataclass
class RecordingInfo:
    path: Path
    subject: str = ""
    created: str = ""
    seconds: float | None = None
    sensors: tuple[str, ...] = ()
    insoles: bool = False
    markers: int = 0
    model: str = ""
    problem: str | None = None


def _last_finite(ds) -> float | None:
    """The last written time of a dataset whose unwritten rows read NaN (a live or killed
    recording): read backwards a chunk at a time, usually once."""
    n = ds.shape[0]
    step = 1024
    end = n
    while end > 0:
        block = np.asarray(ds[max(0, end - step):end], dtype=float)
        ok = np.flatnonzero(np.isfinite(block))
        if len(ok):
            return float(block[ok[-1]])
        end -= step
    return None


def recording_info(path: Path) -> RecordingInfo:
    """The header of one recording, or a ``problem`` saying why it cannot be listed."""
    from app.recording import fixed_dataset, open_recording_header

    info = RecordingInfo(path)
    try:
        f, attrs = open_recording_header(path)
        with f:
            meta = json.loads(attrs.get("metadata", "{}"))
            info.sensors = tuple(json.loads(attrs.get("sites", "[]")))
            info.created = str(attrs.get("created", ""))
            subject = meta.get("subject")
            info.subject = subject.get("id", "") if isinstance(subject, dict) else str(subject or "")
            info.insoles = bool(meta.get("insoles"))
            info.model = str(meta.get("model") or "")
            t = fixed_dataset(f, "raw/t", path)
            if t.shape[0]:
                first = float(t[0])
                last = _last_finite(t)
                if np.isfinite(first) and last is not None:
                    info.seconds = last - first
            if "events/kind" in f:
                kinds = np.asarray(fixed_dataset(f, "events/kind", path)[:])
                info.markers = int(np.sum(kinds == b"marker"))
    except Exception as exc:  # a damaged or foreign file is listed with its problem, not fatal
        info.problem = " ".join(str(exc).split())
    if not info.created:
        info.created = time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(path.stat().st_mtime))
    return info


def scan_folder(folder: Path) -> list[RecordingInfo]:
    files = sorted(Path(folder).glob("*.h5"), key=lambda p: p.stat().st_mtime, reverse=True)
    return [recording_info(p) for p in files]


def fmt_length(seconds: float | None) -> str:
    if seconds is None:
        return "–"
    m, s = divmod(int(round(seconds)), 60)
    return f"{m}:{s:02d}"


def report_path(recording: Path) -> Path:
    """Where the window writes a recording's gait report: beside it, ``<name>_report.html``."""
    return Path(recording).with_name(Path(recording).stem + "_report.html")


def write_report(recording: Path, late: bool = False) -> dict:
    """The gait report of ``recording`` (``imucap report REC --out <report_path>``); its figures, and under
    ``posed`` which poses it read. ``late``: a recording whose poses were the newest frame's (a live capture)
    is posed again as an import is, with the full model ``OFFLINE_ANSWER_LAG`` frames late, as ``imucap
    report`` does by default (``app.report.build.poses_to_report``: the knees of docs/report.md's walks 13.1
    -> 5.9 deg off with pelvis + shanks); one that cannot be replayed (no raw stream, no calibration, damage)
    is reported on its own poses, and says so. Not ``late``: its own poses."""
    from app.report import make_report
    from app.report.build import poses_to_report

    rec, posed = poses_to_report(recording, None if late else 0)
    summary = make_report(rec, report_path(recording)).summary
    summary["posed"] = posed
    return summary


class RecordingsPanel(QtWidgets.QWidget):
    openRequested = QtCore.Signal(str)
    reportWritten = QtCore.Signal(str)  # the report's path, once written

    def __init__(self, jobs: Jobs, report: Callable[[str, str], None],
                 parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.jobs, self.report = jobs, report
        self.folder: Path | None = None
        self.infos: list[RecordingInfo] = []
        lay = QtWidgets.QVBoxLayout(self)
        row = QtWidgets.QHBoxLayout()
        self.folder_label = QtWidgets.QLabel("no folder")
        refresh = QtWidgets.QPushButton("Refresh")
        refresh.clicked.connect(self.refresh)
        other = QtWidgets.QPushButton("Open a recording…")
        other.clicked.connect(self._open_other)
        self.open_button = QtWidgets.QPushButton("Open in replay")
        self.open_button.clicked.connect(self._open_selected)
        self.report_button = QtWidgets.QPushButton("Gait report")
        self.report_button.setToolTip("write a gait report of the selected recording beside it "
                                      "(<name>_report.html: strides, joint angles over the gait cycle, how sure)")
        self.report_button.clicked.connect(self.report_selected)
        self.late_box = QtWidgets.QCheckBox("pose again 200 ms late")
        self.late_box.setChecked(True)
        self.late_box.setToolTip("before the report, pose a live capture again as an import is: each pose as "
                                 "the model answered it 4 frames later (a replay, ~0.4 of the recording's "
                                 "length; the inferred knees' range nearer the truth)")
        row.addWidget(self.folder_label, 1)
        for b in (refresh, other, self.open_button, self.report_button, self.late_box):
            row.addWidget(b)
        lay.addLayout(row)
        self.report_link = QtWidgets.QLabel("")
        self.report_link.setOpenExternalLinks(True)
        self.report_link.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextBrowserInteraction)
        lay.addWidget(self.report_link)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        hh = self.table.horizontalHeader()
        hh.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        hh.setSectionResizeMode(4, QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.doubleClicked.connect(lambda _i: self._open_selected())
        lay.addWidget(self.table, 1)

    def set_folder(self, folder: Path) -> None:
        if folder != self.folder:
            self.folder = Path(folder)
            self.refresh()

    def refresh(self) -> None:
        if self.folder is None:
            return
        self.folder_label.setText(f"<b>{self.folder}</b> (scanning…)")
        if not self.folder.is_dir():
            self._listed([])
            return
        self.jobs.run("scan-recordings", scan_folder, self.folder, on_done=self._listed,
                      on_error=lambda e: self.report(f"cannot list {self.folder}: {e}", "error"))

    def _listed(self, infos: list[RecordingInfo]) -> None:
        self.infos = infos
        self.folder_label.setText(f"<b>{self.folder}</b>: {len(infos)} recording(s)")
        self.table.setRowCount(len(infos))
        for r, i in enumerate(infos):
            sensors = ", ".join(i.sensors) + (" + insoles" if i.insoles else "")
            vals = (i.path.name, i.subject, i.created.replace("T", " ")[:19], fmt_length(i.seconds),
                    i.problem or sensors, str(i.markers), i.model)
            for c, v in enumerate(vals):
                item = QtWidgets.QTableWidgetItem(v)
                item.setToolTip(str(i.path) if c == 0 else v)
                self.table.setItem(r, c, item)

    def _open_selected(self) -> None:
        rows = self.table.selectionModel().selectedRows()
        if not rows:
            self.report("select a recording first", "warning")
            return
        self.openRequested.emit(str(self.infos[rows[0].row()].path))

    def report_selected(self) -> None:
        """A gait report of the selected recording, made on a thread (reading and analysing a long
        recording takes seconds); the button waits for it."""
        rows = self.table.selectionModel().selectedRows()
        if not rows:
            self.report("select a recording first", "warning")
            return
        path = self.infos[rows[0].row()].path
        self.report_button.setEnabled(False)
        self.report_link.setText(f"writing the gait report of {path.name}…")

        def done(summary: dict) -> None:
            self.report_button.setEnabled(True)
            out = Path(summary["html"])
            n = summary["strides"]
            what = (f"{n['l']} + {n['r']} walking strides, cadence {summary['cadence_spm']:.1f} steps/min"
                    if summary["cadence_spm"] is not None else "no walking found")
            self.report_link.setText(f'Gait report: <a href="{out.resolve().as_uri()}">{out.name}</a> ({what}; '
                                     f'{summary["posed"]})')
            self.report(f"gait report written: {out}", "ok")
            self.reportWritten.emit(str(out))

        def failed(exc: BaseException) -> None:
            self.report_button.setEnabled(True)
            self.report_link.setText("")
            self.report(f"no gait report of {path.name}: {exc}", "error")

        self.jobs.run("gait-report", write_report, path, self.late_box.isChecked(), on_done=done, on_error=failed)

    def _open_other(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open a recording", str(self.folder or ""),
                                                        "Recordings (*.h5 *.hdf5)")
        if path:
            self.openRequested.emit(path)
