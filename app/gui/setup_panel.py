"""Setup: who is captured, which sites carry sensors, insoles, model, calibration, and the
setup file it all lives in.

Why sites are chosen on the figure and presets sit beside it: a clinician thinks "ankles
and pelvis", not in site names; a researcher wants the paper's best three for the legs
without looking them up. Either way the result is the same file ``imucap capture
--setup`` reads, so a setup made here works from the terminal and back.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from app.capture.setup_file import (
    CALIBRATION_PROTOCOLS,
    DEFAULT_MODEL,
    HEIGHT_RANGE_M,
    SetupError,
    load_setup,
    save_setup,
)
from app.gui.body_figure import BodyFigure
from app.gui.presets import PRESETS, preset, sites_of
from app.gui.setup_model import SetupModel

MODELS = (DEFAULT_MODEL, "diffusion", "fast", "regressor", "floor")
Report = Callable[[str, str], None]


class SetupPanel(QtWidgets.QWidget):
    fileChanged = QtCore.Signal(str)  # a setup file was opened or saved: remember it

    def __init__(self, model: SetupModel, report: Report, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.report = report
        self._updating = False
        lay = QtWidgets.QHBoxLayout(self)

        # --- the figure and the presets
        left = QtWidgets.QVBoxLayout()
        self.figure = BodyFigure()
        self.figure.siteClicked.connect(self.model.toggle_site)
        left.addWidget(QtWidgets.QLabel("<b>Sensor sites</b> (click to choose; facing you)"))
        left.addWidget(self.figure, 1)
        self.sites_label = QtWidgets.QLabel()
        self.sites_label.setWordWrap(True)
        left.addWidget(self.sites_label)
        lay.addLayout(left, 2)

        right = QtWidgets.QVBoxLayout()
        box = QtWidgets.QGroupBox("Preset")
        bl = QtWidgets.QVBoxLayout(box)
        self.preset = QtWidgets.QComboBox()
        self.preset.addItem("choose a preset…", None)
        for p in PRESETS:
            self.preset.addItem(p.name, p.name)
            self.preset.setItemData(self.preset.count() - 1, p.why, QtCore.Qt.ItemDataRole.ToolTipRole)
        self.preset.activated.connect(self._preset_chosen)
        self.preset_why = QtWidgets.QLabel()
        self.preset_why.setWordWrap(True)
        self.preset_why.setStyleSheet("color: #556")
        clear = QtWidgets.QPushButton("Clear sites")
        clear.clicked.connect(lambda: self.model.set_sites(()))
        bl.addWidget(self.preset)
        bl.addWidget(self.preset_why)
        self.insoles = QtWidgets.QCheckBox("Pressure insoles (foot contacts)")
        self.insoles.toggled.connect(lambda on: self._edit(insoles=on))
        self.insoles_url = QtWidgets.QLineEdit()
        self.insoles_url.setPlaceholderText("moticon-udp://127.0.0.1:9999")
        self.insoles_url.editingFinished.connect(lambda: self._edit(insoles_url=self.insoles_url.text().strip()))
        bl.addWidget(self.insoles)
        bl.addWidget(self.insoles_url)
        bl.addWidget(clear)
        right.addWidget(box)

        # --- the subject
        box = QtWidgets.QGroupBox("Subject")
        form = QtWidgets.QFormLayout(box)
        self.subject_id = QtWidgets.QLineEdit()
        self.subject_id.editingFinished.connect(lambda: self._edit(subject_id=self.subject_id.text().strip()))
        self.height = QtWidgets.QDoubleSpinBox()
        self.height.setRange(*HEIGHT_RANGE_M)
        self.height.setDecimals(2)
        self.height.setSingleStep(0.01)
        self.height.setSuffix(" m")
        self.height.valueChanged.connect(lambda v: self._edit(height_m=float(v)))
        self.notes = QtWidgets.QPlainTextEdit()
        self.notes.setPlaceholderText("diagnosis, side affected, anything the next person should know")
        self.notes.setMaximumHeight(70)
        self.notes.textChanged.connect(lambda: self._edit(notes=self.notes.toPlainText()))
        form.addRow("Subject id", self.subject_id)
        form.addRow("Height", self.height)
        form.addRow("Notes", self.notes)
        right.addWidget(box)

        # --- model, calibration, where recordings go
        box = QtWidgets.QGroupBox("Capture")
        form = QtWidgets.QFormLayout(box)
        self.protocol = QtWidgets.QComboBox()
        for k, v in CALIBRATION_PROTOCOLS.items():
            self.protocol.addItem(f"{k}: {v}", k)
        self.protocol.activated.connect(lambda i: self._edit(calibration=self.protocol.itemData(i)))
        self.model_name = QtWidgets.QComboBox()
        self.model_name.setEditable(True)
        self.model_name.addItems(MODELS)
        self.model_name.setToolTip("auto (the default: a third of the full model's compute, the full model where a "
                                   "thigh is worn without its shank), diffusion (the full model), fast (the 21-frame "
                                   "file always), regressor, floor (no model), or the path of a model file")
        self.model_name.currentTextChanged.connect(lambda t: self._edit(model=t.strip() or DEFAULT_MODEL))
        self.steps = QtWidgets.QLineEdit()
        self.steps.setPlaceholderText("the model's own (e.g. 10D:3)")
        self.steps.editingFinished.connect(lambda: self._edit(steps=self.steps.text().strip() or None))
        folder_row = QtWidgets.QHBoxLayout()
        self.folder = QtWidgets.QLineEdit()
        self.folder.editingFinished.connect(lambda: self._edit(recordings=Path(self.folder.text().strip()
                                                                               or "recordings")))
        browse = QtWidgets.QPushButton("…")
        browse.setFixedWidth(30)
        browse.clicked.connect(self._browse_folder)
        folder_row.addWidget(self.folder)
        folder_row.addWidget(browse)
        form.addRow("Calibration", self.protocol)
        form.addRow("Model", self.model_name)
        form.addRow("Steps", self.steps)
        form.addRow("Recordings", folder_row)
        right.addWidget(box)

        # --- the file
        box = QtWidgets.QGroupBox("Setup file")
        fl = QtWidgets.QVBoxLayout(box)
        self.path_label = QtWidgets.QLabel("not saved yet")
        self.path_label.setWordWrap(True)
        row = QtWidgets.QHBoxLayout()
        for text, slot in (("Open…", self._open_dialog), ("Save", self.save), ("Save as…", self._save_dialog)):
            b = QtWidgets.QPushButton(text)
            b.clicked.connect(slot)
            row.addWidget(b)
        fl.addWidget(self.path_label)
        fl.addLayout(row)
        right.addWidget(box)
        right.addStretch(1)
        lay.addLayout(right, 3)

        model.changed.connect(self.refresh)
        self.refresh()

    # ------------------------------------------------------------------ model -> widgets
    def refresh(self) -> None:
        d = self.model.draft
        self._updating = True
        try:
            self.figure.set_state(d.sites, self.model.assigned(), insoles=d.insoles)
            missing = self.model.unassigned()
            text = f"<b>{len(d.sites)} site(s)</b>: {', '.join(d.sites) or 'none'}"
            if missing:
                text += f"<br><span style='color:#b06000'>no device yet: {', '.join(missing)}</span>"
            self.sites_label.setText(text)
            for w, v in ((self.subject_id, d.subject_id), (self.insoles_url, d.insoles_url),
                         (self.steps, d.steps or ""), (self.folder, str(d.recordings))):
                if w.text() != v and not w.hasFocus():
                    w.setText(v)
            if abs(self.height.value() - d.height_m) > 1e-9:
                self.height.setValue(d.height_m)
            if self.notes.toPlainText() != d.notes and not self.notes.hasFocus():
                self.notes.setPlainText(d.notes)
            self.insoles.setChecked(d.insoles)
            self.insoles_url.setEnabled(d.insoles)
            self.protocol.setCurrentIndex(max(self.protocol.findData(d.calibration), 0))
            if self.model_name.currentText() != d.model:
                self.model_name.setCurrentText(d.model)
            self.path_label.setText(str(d.path) if d.path else "not saved yet")
        finally:
            self._updating = False

    def _edit(self, **fields: object) -> None:
        if not self._updating:
            self.model.update(**fields)

    # ------------------------------------------------------------------ actions
    def choose_preset(self, name: str) -> None:
        p = preset(name)
        self.model.set_sites(sites_of(p, dict(self.model.draft.urls)))
        self.preset_why.setText(p.why)
        i = self.preset.findData(p.name)
        if i >= 0:
            self.preset.setCurrentIndex(i)

    def _preset_chosen(self, i: int) -> None:
        name = self.preset.itemData(i)
        if name:
            self.choose_preset(name)

    def _browse_folder(self) -> None:
        folder = QtWidgets.QFileDialog.getExistingDirectory(self, "Recordings folder", str(self.model.draft.recordings))
        if folder:
            self.model.update(recordings=Path(folder))

    def _open_dialog(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open setup", "", "Setup files (*.toml);;All files (*)")
        if path:
            self.open(path)

    def _save_dialog(self) -> None:
        start = str(self.model.draft.path or f"{self.model.draft.subject_id}.toml")
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save setup", start, "Setup files (*.toml)")
        if path:
            self.save_to(path)

    def open(self, path: str | Path) -> bool:
        try:
            setup = load_setup(path)
        except (SetupError, OSError) as exc:
            self.report(str(exc), "error")
            return False
        self.model.load(setup)
        self.report(f"opened {path}", "ok")
        self.fileChanged.emit(str(Path(path).resolve()))
        return True

    def save(self) -> bool:
        if self.model.draft.path is None:
            self._save_dialog()
            return self.model.draft.path is not None
        return self.save_to(self.model.draft.path)

    def save_to(self, path: str | Path) -> bool:
        target = Path(path).resolve()
        try:
            setup = self.model.to_setup()
            recordings = setup.recordings
            if not recordings.is_absolute() and self.model.draft.path is not None:
                recordings = self.model.draft.path.parent / recordings  # the folder stays where it was
            setup.recordings = recordings
            setup.path = target
            save_setup(setup, target)
        except (SetupError, OSError) as exc:
            self.report(f"not saved: {exc}", "error")
            return False
        self.model.update(path=target, recordings=load_setup(target).recordings)
        self.report(f"saved {target}", "ok")
        self.fileChanged.emit(str(target))
        return True
