"""Replay: a recording's reconstruction on a timeline, re-run with another sensor subset or
model beside it, how far apart the two are per segment, and export.

Why side by side with the difference: the researcher's question is "what would three
sensors have given on this session?"; two skeletons moving together show where they part,
and the per-segment angle says by how much, on the same frames (the paper's GA). The
re-run is ``app.replay.replay_recording``, the very code of ``imucap replay``, on a
worker thread.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore, QtWidgets

from app.gui import views
from app.gui.colours import RERUN, difference_colours, qcolor_tuple, segment_colours
from app.gui.widgets import Legend
from app.gui.workers import Job, Jobs
from app.recording import Recording
from inference.body.body import Body
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import METRIC_EXCLUDED, SEGMENTS, SITES

SIDE_BY_SIDE_M = 1.1  # the re-run stands this far to the subject's left: right of it on screen
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0)
FORMATS = {".bvh": "BVH (Blender, MotionBuilder, Maya)", ".mot": "OpenSim motion (.mot, joint angles)",
           ".csv": "CSV (one row per frame)", ".h5": "HDF5 (arrays with units)", ".hdf5": "HDF5 (arrays with units)"}
Report = Callable[[str, str], None]


@dataclass
class Track:
    """One skeleton's frames on the recording's clock."""

    label: str
    t: np.ndarray  # (M,)
    R: np.ndarray  # (M, 24, 3, 3)
    joints: np.ndarray  # (M, 24, 3)
    contacts: np.ndarray  # (M, 4)
    observed: np.ndarray  # (M, 13)
    spread: np.ndarray | None = None  # (M, 24)
    poses: list[Any] | None = None  # the re-run's LivePoses, for export
    sensors: tuple[str, ...] = ()
    model: str = ""


def track_from_recording(rec: Recording) -> Track:
    r = rec.recon
    return Track(f"recorded live: {', '.join(rec.metadata.get('sensors') or rec.sites)}", np.asarray(r["t"], float),
                 np.asarray(r["R"], float), np.asarray(r["joints"], float), np.asarray(r["contacts"], bool),
                 np.asarray(r["observed_sites"], bool), sensors=tuple(rec.metadata.get("sensors") or rec.sites),
                 model=str(rec.metadata.get("model") or ""))


def track_from_poses(poses: list[Any], sensors: tuple[str, ...], model: str) -> Track:
    spread = [getattr(p.pose, "spread_deg", None) for p in poses]
    return Track(f"re-run: {', '.join(sensors)} ({model})", np.array([p.t for p in poses]),
                 np.stack([p.pose.rot for p in poses]), np.stack([p.pose.joints for p in poses]),
                 np.stack([p.pose.contacts for p in poses]), np.stack([p.observed_sites for p in poses]),
                 spread=np.stack(spread) if poses and all(s is not None for s in spread) else None,
                 poses=poses, sensors=sensors, model=model)


def segment_differences(ref: Track, other: Track, index: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """(M, 24) angle (deg) between the two per frame (NaN where the re-run has no frame),
    and a summary: GA over the paper's segments, per segment means, frames compared."""
    diff = np.full((len(ref.t), len(SEGMENTS)), np.nan)
    ok = index >= 0
    if ok.any():
        diff[ok] = np.degrees(matrix_angle_between(ref.R[ok], other.R[index[ok]]))
    evaluated = [k for k, s in enumerate(SEGMENTS) if s not in METRIC_EXCLUDED]
    per_segment = {SEGMENTS[k]: float(np.nanmean(diff[ok, k])) for k in evaluated} if ok.any() else {}
    ga = float(np.nanmean(diff[ok][:, evaluated])) if ok.any() else None
    return diff, {"ga_deg": ga, "frames": int(ok.sum()), "segments": per_segment}


# the Re-run's model box: the model the session was posed with, as ``imucap replay`` with no --model
AS_RECORDED = "as recorded"


def rerun_model(text: str) -> str | None:
    """The model spec the Re-run box names (None: as recorded)."""
    text = text.strip()
    return None if text in ("", AS_RECORDED) else text


def rerun(job: Job, rec: Recording, sensors: tuple[str, ...], insoles: bool, model_spec: str | None,
          steps: str | None, confidence: bool = False) -> Track:
    """The worker: a poser for ``model_spec`` (None: the recorded model) and the recording's
    body, then the replay."""
    from app.export.formats import body_for_recording
    from app.live.model_choice import FLOOR_FALLBACK_LABEL, choose_model, set_torch_threads
    from app.replay import ReplaySettings, build_replay_poser, replay_model, replay_recording

    set_torch_threads(1)  # leave the other core to the window and the devices
    job.report((0, 1, "loading the model"))
    latency = rec.metadata.get("latency") or "centred"
    model_spec = replay_model(rec, ReplaySettings(model=model_spec), sensors)
    # the window falls back to the floor, as live, where the CLI replay would stop
    choice = choose_model(model_spec, latency, fallback=True)
    body, _ = body_for_recording(rec.metadata)
    # the poser as the session ran it (steps, mirror, root, filter from the recording), with
    # what the user changed here: the same code as `imucap replay`
    built = build_replay_poser(rec, ReplaySettings(model=model_spec, steps=steps, confidence=confidence or None),
                               body, model=choice.model)
    res = replay_recording(rec, built.poser, sensors=list(sensors), insoles=insoles, causal=built.causal,
                           progress=lambda done, total, poses: job.report((done, total, f"{poses} poses")))
    track = track_from_poses(res.poses, res.sensors, built.label)
    if choice.label == FLOOR_FALLBACK_LABEL:
        track.label += " [floor baseline: weights missing]"
    return track


class ExportDialog(QtWidgets.QDialog):
    """Which reconstruction, which format (every one ``app.export`` writes), where."""

    def __init__(self, parent: QtWidgets.QWidget, sources: list[str], folder: Path, stem: str) -> None:
        super().__init__(parent)
        from app.export.formats import WRITERS

        self.setWindowTitle("Export")
        form = QtWidgets.QFormLayout(self)
        self.source = QtWidgets.QComboBox()
        self.source.addItems(sources)
        self.source.setCurrentIndex(len(sources) - 1)
        self.format = QtWidgets.QComboBox()
        for ext in WRITERS:
            self.format.addItem(f"{ext}  {FORMATS.get(ext, '')}", ext)
        self.path = QtWidgets.QLineEdit(str(folder / f"{stem}{self.format.currentData()}"))
        self.format.currentIndexChanged.connect(self._format_changed)
        browse = QtWidgets.QPushButton("…")
        browse.clicked.connect(self._browse)
        row = QtWidgets.QHBoxLayout()
        row.addWidget(self.path, 1)
        row.addWidget(browse)
        form.addRow("Reconstruction", self.source)
        form.addRow("Format", self.format)
        form.addRow("File", row)
        buttons = QtWidgets.QDialogButtonBox(QtWidgets.QDialogButtonBox.StandardButton.Ok
                                             | QtWidgets.QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        self.ok_button = buttons.button(QtWidgets.QDialogButtonBox.StandardButton.Ok)
        self.ok_button.setText("Export")
        form.addRow(buttons)

    def set_format(self, ext: str) -> None:
        self.format.setCurrentIndex(self.format.findData(ext))

    def _format_changed(self) -> None:
        p = Path(self.path.text())
        self.path.setText(str(p.with_suffix(self.format.currentData())))

    def _browse(self) -> None:
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Export to", self.path.text())
        if path:
            self.path.setText(path)


class ReplayPanel(QtWidgets.QWidget):
    def __init__(self, jobs: Jobs, report: Report, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.jobs, self.report = jobs, report
        self.rec: Recording | None = None
        self.body: Body | None = None
        self.ref: Track | None = None
        self.other: Track | None = None
        self.index = np.zeros(0, int)
        self.diff: np.ndarray | None = None
        self.summary: dict[str, Any] = {}
        self.frame = 0
        self.playing = False
        self.rerun_job: Job | None = None
        self.export_dialog: ExportDialog | None = None
        self.exported: list[Path] = []
        self._play_clock: tuple[float, float] | None = None  # (wall time, recording time) at play

        lay = QtWidgets.QHBoxLayout(self)
        left = QtWidgets.QVBoxLayout()
        row = QtWidgets.QHBoxLayout()
        self.file_label = QtWidgets.QLabel("Open a recording from the Recordings tab")
        self.markers = QtWidgets.QComboBox()
        self.markers.setMinimumWidth(140)
        self.markers.activated.connect(self._jump_to_marker)
        row.addWidget(self.file_label, 1)
        row.addWidget(QtWidgets.QLabel("Markers:"))
        row.addWidget(self.markers)
        left.addLayout(row)
        self.ref_label = QtWidgets.QLabel("")
        self.other_label = QtWidgets.QLabel("")
        self.other_label.setStyleSheet(f"color: rgb{qcolor_tuple(RERUN)}; font-weight: bold")
        labels = QtWidgets.QHBoxLayout()
        labels.addWidget(self.ref_label, 1)
        labels.addWidget(self.other_label, 1)
        left.addLayout(labels)
        self.view = views.make_skeleton_view(None)  # put in by views.add_view below
        self.view.add_figure(RERUN)
        self.view.follow = False
        self.view.set_view("pair")
        self.view.set_figure_visible(1, False)
        views.add_view(self, left, self.view, 1)
        self.legend = Legend()
        left.addWidget(self.legend)

        row = QtWidgets.QHBoxLayout()
        self.play_button = QtWidgets.QPushButton("▶ Play (Space)")
        self.play_button.clicked.connect(self.toggle_play)
        self.slider = QtWidgets.QSlider(QtCore.Qt.Orientation.Horizontal)
        self.slider.valueChanged.connect(self._slider_moved)
        self.speed = QtWidgets.QComboBox()
        for s in SPEEDS:
            self.speed.addItem(f"{s:g}×", s)
        self.speed.setCurrentIndex(SPEEDS.index(1.0))
        self.time_label = QtWidgets.QLabel("0.0 / 0.0 s")
        row.addWidget(self.play_button)
        row.addWidget(self.slider, 1)
        row.addWidget(self.speed)
        row.addWidget(self.time_label)
        left.addLayout(row)
        lay.addLayout(left, 3)

        right = QtWidgets.QVBoxLayout()
        box = QtWidgets.QGroupBox("Re-run with")
        bl = QtWidgets.QVBoxLayout(box)
        self.site_grid = QtWidgets.QGridLayout()
        self.site_checks: dict[str, QtWidgets.QCheckBox] = {}
        bl.addLayout(self.site_grid)
        self.insoles = QtWidgets.QCheckBox("insoles")
        bl.addWidget(self.insoles)
        form = QtWidgets.QFormLayout()
        self.model = QtWidgets.QComboBox()
        self.model.setEditable(True)
        self.model.addItems([AS_RECORDED, "diffusion", "fast", "auto", "regressor", "floor"])
        self.steps = QtWidgets.QLineEdit()
        self.steps.setPlaceholderText("the model's own")
        form.addRow("Model", self.model)
        form.addRow("Steps", self.steps)
        bl.addLayout(form)
        self.confidence = QtWidgets.QCheckBox("with each segment's spread (diffusion; slower)")
        self.confidence.setToolTip("other inpaintings of each frame: how sure the model is of each segment it "
                                   "did not measure; shown when the re-run is not coloured by its difference")
        bl.addWidget(self.confidence)
        row = QtWidgets.QHBoxLayout()
        self.rerun_button = QtWidgets.QPushButton("Re-run")
        self.rerun_button.clicked.connect(self.start_rerun)
        self.cancel_button = QtWidgets.QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.cancel_button.clicked.connect(self.cancel_rerun)
        row.addWidget(self.rerun_button)
        row.addWidget(self.cancel_button)
        bl.addLayout(row)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setValue(0)
        bl.addWidget(self.progress)
        right.addWidget(box)

        box = QtWidgets.QGroupBox("Difference (re-run vs recorded)")
        bl = QtWidgets.QVBoxLayout(box)
        self.ga_label = QtWidgets.QLabel("re-run to compare")
        self.ga_label.setWordWrap(True)
        self.colour_by_diff = QtWidgets.QCheckBox("colour the re-run by its difference (green 0° … red 30°+)")
        self.colour_by_diff.setChecked(True)
        self.colour_by_diff.toggled.connect(lambda _on: self.show_frame(self.frame))
        self.diff_table = QtWidgets.QTableWidget(0, 3)
        self.diff_table.setHorizontalHeaderLabels(("segment", "mean °", "now °"))
        self.diff_table.verticalHeader().setVisible(False)
        self.diff_table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.diff_table.horizontalHeader().setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.Stretch)
        bl.addWidget(self.ga_label)
        bl.addWidget(self.colour_by_diff)
        bl.addWidget(self.diff_table, 1)
        right.addWidget(box, 1)
        self.export_button = QtWidgets.QPushButton("Export…")
        self.export_button.setEnabled(False)
        self.export_button.clicked.connect(self.open_export_dialog)
        right.addWidget(self.export_button)
        lay.addLayout(right, 2)

        # Space plays and pauses (the window's shortcut): a focused button would take it as a click
        for b in (self.play_button, self.rerun_button, self.cancel_button, self.export_button):
            b.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.timer = QtCore.QTimer(self)
        self.timer.timeout.connect(self._tick)
        self.timer.start(33)

    # ------------------------------------------------------------------ loading
    def open(self, path: str | Path) -> None:
        from app.export.formats import body_for_recording
        from app.recording import read_recording

        def load(p: Path) -> tuple[Recording, Body, str | None]:
            rec = read_recording(p)
            body, note = body_for_recording(rec.metadata)
            return rec, body, note

        self.file_label.setText(f"loading {Path(path).name}…")
        self.jobs.run("load-recording", load, Path(path), on_done=self._loaded,
                      on_error=lambda e: self._load_failed(path, e))

    def _load_failed(self, path: str | Path, exc: BaseException) -> None:
        self.file_label.setText("no recording")
        self.report(f"cannot open {path}: {exc}", "error")

    def _loaded(self, result: tuple[Recording, Body, str | None]) -> None:
        rec, body, note = result
        if len(rec.recon["t"]) == 0:
            self.report(f"{rec.path.name} holds no reconstructed frames (the session never calibrated); "
                        "re-run it to reconstruct", "warning")
        self.rec, self.body = rec, body
        self.ref = track_from_recording(rec)
        self.other, self.diff, self.summary = None, None, {}
        self.index = np.zeros(len(self.ref.t), int) - 1
        self.file_label.setText(f"<b>{rec.path.name}</b>  {rec.metadata.get('subject', {}).get('id', '')}"
                                f"  {len(self.ref.t)} frames")
        self.ref_label.setText(self.ref.label)
        self.other_label.setText("")
        self.view.set_figure_visible(1, False)
        self.markers.clear()
        self.markers.addItem("–", None)
        t0 = float(rec.raw["t"][0]) if rec.n_frames else 0.0
        for t, label in rec.markers():
            self.markers.addItem(f"{t - t0:6.1f} s  {label}", t)
        for cb in self.site_checks.values():
            cb.deleteLater()
        self.site_checks = {}
        for k, s in enumerate(rec.sites):
            cb = QtWidgets.QCheckBox(s)
            cb.setChecked(True)
            self.site_grid.addWidget(cb, k // 3, k % 3)
            self.site_checks[s] = cb
        from app.replay import recording_has_insoles

        has = recording_has_insoles(rec)
        self.insoles.setEnabled(has)
        self.insoles.setChecked(has and bool(rec.metadata.get("insoles")))
        self.slider.setRange(0, max(len(self.ref.t) - 1, 0))
        self.frame = 0
        self.slider.setValue(0)
        self.diff_table.setRowCount(0)
        self.ga_label.setText("re-run to compare")
        self.export_button.setEnabled(len(self.ref.t) > 0)
        if note:
            self.report(note, "warning")
        self.show_frame(0)

    # ------------------------------------------------------------------ re-run
    def choose_sensors(self, sites: tuple[str, ...] | list[str]) -> None:
        for s, cb in self.site_checks.items():
            cb.setChecked(s in sites)

    def start_rerun(self) -> None:
        if self.rec is None:
            self.report("open a recording first", "warning")
            return
        sites = tuple(s for s in SITES if s in self.site_checks and self.site_checks[s].isChecked())
        if not sites:
            self.report("choose at least one sensor to re-run with", "warning")
            return
        self.rerun_button.setEnabled(False)
        self.cancel_button.setEnabled(True)
        self.progress.setValue(0)
        self.rerun_job = self.jobs.run("rerun", rerun, self.rec, sites, self.insoles.isChecked(),
                                       rerun_model(self.model.currentText()),
                                       self.steps.text().strip() or None, self.confidence.isChecked(),
                                       on_done=self._rerun_done,
                                       on_error=self._rerun_failed, with_job=True)

    def cancel_rerun(self) -> None:
        if self.rerun_job is not None:
            self.rerun_job.cancel()

    def _rerun_failed(self, exc: BaseException) -> None:
        from app.gui.workers import Cancelled

        self.rerun_job = None
        self.rerun_button.setEnabled(True)
        self.cancel_button.setEnabled(False)
        self.progress.setValue(0)
        if isinstance(exc, Cancelled):
            self.report("re-run cancelled", "info")
        else:
            self.report(f"re-run failed: {exc}", "error")

    def _rerun_done(self, track: Track) -> None:
        self.rerun_job = None
        self.rerun_button.setEnabled(True)
        self.cancel_button.setEnabled(False)
        self.progress.setValue(1000)
        assert self.ref is not None
        self.other = track
        from app.replay import match_times

        self.index = match_times(self.ref.t, track.t)
        self.diff, self.summary = segment_differences(self.ref, track, self.index)
        self.other_label.setText(track.label)
        self.view.set_figure_visible(1, True)
        ga = self.summary["ga_deg"]
        self.ga_label.setText(f"<b>GA between them: {'–' if ga is None else f'{ga:.1f}°'}</b> over "
                              f"{self.summary['frames']} frames (the paper's segments)")
        worst = sorted(self.summary["segments"].items(), key=lambda kv: -kv[1])
        self.diff_table.setRowCount(len(worst))
        for r, (seg, v) in enumerate(worst):
            self.diff_table.setItem(r, 0, QtWidgets.QTableWidgetItem(seg))
            self.diff_table.setItem(r, 1, QtWidgets.QTableWidgetItem(f"{v:.1f}"))
            self.diff_table.setItem(r, 2, QtWidgets.QTableWidgetItem(""))
        self.report(f"re-run with {', '.join(track.sensors)}: {len(track.t)} frames, "
                    f"GA {'–' if ga is None else f'{ga:.1f}°'} from the recorded reconstruction", "ok")
        self.show_frame(self.frame)

    # ------------------------------------------------------------------ playback
    def toggle_play(self) -> None:
        if self.ref is None or len(self.ref.t) == 0:
            return
        self.playing = not self.playing
        if self.playing and self.frame >= len(self.ref.t) - 1:
            self.frame = 0
        self._play_clock = (time.monotonic(), float(self.ref.t[self.frame])) if self.playing else None
        self.play_button.setText("❚❚ Pause (Space)" if self.playing else "▶ Play (Space)")

    def _tick(self) -> None:
        if self.rerun_job is not None and self.rerun_job.progress:
            done, total, _what = self.rerun_job.progress
            self.progress.setValue(int(1000 * done / max(total, 1)))
        if not self.playing or self.ref is None or self._play_clock is None:
            return
        wall0, t0 = self._play_clock
        t = t0 + (time.monotonic() - wall0) * float(self.speed.currentData())
        k = int(np.searchsorted(self.ref.t, t))
        if k >= len(self.ref.t) - 1:
            k = len(self.ref.t) - 1
            self.toggle_play()
        self.slider.setValue(k)

    def _slider_moved(self, k: int) -> None:
        if self.playing and self.slider.isSliderDown() and self.ref is not None:
            self._play_clock = (time.monotonic(), float(self.ref.t[k]))  # dragged: play on from there
        self.show_frame(k)

    def _jump_to_marker(self, i: int) -> None:
        t = self.markers.itemData(i)
        if t is None or self.ref is None or not len(self.ref.t):
            return
        k = int(np.clip(np.searchsorted(self.ref.t, t), 0, len(self.ref.t) - 1))
        if self.playing:
            self._play_clock = (time.monotonic(), float(self.ref.t[k]))
        self.slider.setValue(k)

    def show_frame(self, k: int) -> None:
        ref, body = self.ref, self.body
        if ref is None or body is None or not len(ref.t):
            return
        k = int(np.clip(k, 0, len(ref.t) - 1))
        self.frame = k
        self.view.set_segment_colours(segment_colours(ref.observed[k]))
        self.view.show_pose(ref.joints[k], ref.R[k], ref.contacts[k], body, figure=0)
        right = np.array([0.0, SIDE_BY_SIDE_M, 0.0])
        centre = ref.joints[k, 0].copy()
        j = self.index[k] if len(self.index) > k else -1
        if self.other is not None and j >= 0:
            o = self.other
            if self.colour_by_diff.isChecked() and self.diff is not None:
                colours = difference_colours(self.diff[k])
            else:
                colours = segment_colours(o.observed[j], None if o.spread is None else o.spread[j])
            self.legend.set_spread(o.spread is not None and not self.colour_by_diff.isChecked())
            self.view.set_segment_colours(colours, figure=1)
            # side by side: the re-run's root follows its own path, shifted to the right
            self.view.show_pose(o.joints[j], o.R[j], o.contacts[j], body, figure=1, offset=right)
            self.view.set_figure_visible(1, True)
            centre = centre + right / 2
            if self.diff is not None:
                for r in range(self.diff_table.rowCount()):
                    seg = self.diff_table.item(r, 0).text()
                    v = self.diff[k, SEGMENTS.index(seg)]
                    self.diff_table.item(r, 2).setText("–" if not np.isfinite(v) else f"{v:.1f}")
        elif self.other is not None:
            self.view.set_figure_visible(1, False)
        self.view.look_at(np.array([centre[0], centre[1], 0.9]))
        t0 = float(self.rec.raw["t"][0]) if self.rec is not None and self.rec.n_frames else float(ref.t[0])
        self.time_label.setText(f"{ref.t[k] - t0:5.1f} / {ref.t[-1] - t0:5.1f} s")

    # ------------------------------------------------------------------ export
    def export_sources(self) -> list[str]:
        out = []
        if self.ref is not None and len(self.ref.t):
            out.append("recorded live reconstruction")
        if self.other is not None:
            out.append(self.other.label)
        return out

    def open_export_dialog(self) -> ExportDialog | None:
        if self.rec is None:
            return None
        sources = self.export_sources()
        if not sources:
            self.report("nothing to export: the recording has no reconstruction; re-run it first", "warning")
            return None
        stem = self.rec.path.stem + ("" if self.other is None else "-" + "-".join(self.other.sensors))
        dlg = ExportDialog(self, sources, self.rec.path.parent, stem)
        dlg.accepted.connect(lambda: self.export(dlg.source.currentIndex(), Path(dlg.path.text())))
        self.export_dialog = dlg
        dlg.open()
        return dlg

    def export(self, source: int, path: Path) -> None:
        """Write the chosen reconstruction on a worker thread."""
        from app.export.formats import check_export_path, export_motion, motion_from_poses, motion_from_recording

        rec, body = self.rec, self.body
        if rec is None or body is None:
            return
        try:
            check_export_path(path)
        except ValueError as exc:
            self.report(str(exc), "error")
            return
        use_recorded = self.export_sources()[source] == "recorded live reconstruction"
        other = self.other

        def write() -> Path:
            if use_recorded:
                motion = motion_from_recording(rec, body)
            else:
                assert other is not None
                motion = motion_from_poses(other.poses or [], body, rec, meta={
                    "what": "re-run", "sensors": list(other.sensors), "model": other.model})
            return export_motion(path, motion)

        self.jobs.run("export", write, on_done=self._exported,
                      on_error=lambda e: self.report(f"export to {path} failed: {e}", "error"))

    def _exported(self, path: Path) -> None:
        self.exported.append(Path(path))
        self.report(f"exported {path}", "ok")
