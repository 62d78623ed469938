"""Devices: what is connected, which site each one is on, and how each one is doing.

Why "move the sensor you want": ports are numbered by plug order and CAN ids by a sticker
nobody can read once the strap is on; picking up the sensor is the one way to know which
is which (SlimeVR and the Xsens DOT app do the same). The watcher listens to every device
at once and names one only when it clearly leads, so a bump while strapping another on
does not assign the wrong one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from PySide6 import QtCore, QtGui, QtWidgets

from app.capture.identify import DeviceReaders, MotionWatcher
from app.gui.body_figure import BodyFigure
from app.gui.live_session import DeviceRow
from app.gui.setup_model import SetupModel
from app.gui.widgets import fmt
from app.gui.workers import Jobs

COLUMNS = ("device", "what", "site", "state", "rate", "loss", "battery", "last seen", "motion")
HOLD_S = 0.6  # the same device must lead this long before it is assigned
STATE_COLOURS = {"ok": QtGui.QColor(215, 245, 222), "reconnecting": QtGui.QColor(250, 200, 200),
                 "silent": QtGui.QColor(250, 200, 200), "waiting": QtGui.QColor(240, 240, 240),
                 "problem": QtGui.QColor(255, 236, 190), "moving": QtGui.QColor(255, 240, 120)}
Report = Callable[[str, str], None]


@dataclass
class Identification:
    """One "move the sensor you want" run for ``site``."""

    site: str
    urls: list[str]
    watcher: MotionWatcher
    readers: DeviceReaders
    started: float
    leader: str | None = None
    leading_since: float | None = None
    errors: list[str] = field(default_factory=list)  # devices that could not be opened, and why


class DevicesPanel(QtWidgets.QWidget):
    simulateRequested = QtCore.Signal(str)  # wire protocol: make simulated devices for the chosen sites

    def __init__(self, model: SetupModel, jobs: Jobs, report: Report, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.model, self.jobs, self.report = model, jobs, report
        self.live_rows: dict[str, DeviceRow] = {}  # by URL, while a session runs
        self.checked: dict[str, dict] = {}  # by URL, from the last "Check devices"
        self.speeds: dict[str, float] = {}
        self.identification: Identification | None = None
        self.session_running = False
        self.alarm_sites: set[str] = set()

        lay = QtWidgets.QHBoxLayout(self)
        self.figure = BodyFigure()
        self.figure.siteClicked.connect(self._site_clicked)
        lay.addWidget(self.figure, 1)
        right = QtWidgets.QVBoxLayout()
        lay.addLayout(right, 4)

        row = QtWidgets.QHBoxLayout()
        self.scan_button = QtWidgets.QPushButton("Scan for devices")
        self.scan_button.clicked.connect(self.scan)
        self.url_edit = QtWidgets.QLineEdit()
        self.url_edit.setPlaceholderText("add a device by URL, e.g. xbus:///dev/ttyUSB0?baud=115200")
        self.url_edit.returnPressed.connect(self._add_typed)
        add = QtWidgets.QPushButton("Add")
        add.clicked.connect(self._add_typed)
        self.sim_protocol = QtWidgets.QComboBox()
        self.sim_protocol.addItems(["xbus", "bno08x-rvc", "xsens-can", "dualsense", "mixed"])
        self.sim_button = QtWidgets.QPushButton("Simulate devices")
        self.sim_button.setToolTip("simulated sensors for the chosen sites, worn by a simulated subject who "
                                   "follows the calibration steps: try the whole workflow without hardware")
        self.sim_button.clicked.connect(lambda: self.simulateRequested.emit(self.sim_protocol.currentText()))
        self.check_button = QtWidgets.QPushButton("Check devices")
        self.check_button.setToolTip("open every assigned device for 3 s: rate, loss, battery, problems in words")
        self.check_button.clicked.connect(self.check)
        for w in (self.scan_button, self.url_edit, add, self.sim_protocol, self.sim_button, self.check_button):
            row.addWidget(w)
        row.setStretch(1, 1)
        right.addLayout(row)

        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.setSelectionBehavior(QtWidgets.QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        hh = self.table.horizontalHeader()
        hh.setSectionResizeMode(QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        hh.setSectionResizeMode(0, QtWidgets.QHeaderView.ResizeMode.Stretch)
        self.table.doubleClicked.connect(lambda _i: self.assign_selected())
        right.addWidget(self.table, 1)

        row = QtWidgets.QHBoxLayout()
        row.addWidget(QtWidgets.QLabel("Site:"))
        self.site_combo = QtWidgets.QComboBox()
        self.site_combo.setMinimumWidth(110)
        self.assign_button = QtWidgets.QPushButton("Assign selected device")
        self.assign_button.clicked.connect(self.assign_selected)
        self.unassign_button = QtWidgets.QPushButton("Unassign")
        self.unassign_button.clicked.connect(lambda: self.model.assign(self.site_combo.currentText(), None))
        self.identify_button = QtWidgets.QPushButton("Move the sensor you want…")
        self.identify_button.setToolTip("listen to every device; the one being moved is assigned to the site")
        self.identify_button.clicked.connect(self._identify_clicked)
        for w in (self.site_combo, self.assign_button, self.unassign_button, self.identify_button):
            row.addWidget(w)
        row.addStretch(1)
        right.addLayout(row)
        self.identify_label = QtWidgets.QLabel("")
        self.identify_label.setWordWrap(True)
        right.addWidget(self.identify_label)

        model.changed.connect(self.refresh)
        self._timer = QtCore.QTimer(self)
        self._timer.timeout.connect(self._tick)
        self._timer.start(100)
        self.refresh()

    # ------------------------------------------------------------------ the table
    def urls(self) -> list[str]:
        """Assigned devices first (in site order), then the others as they came."""
        assigned = list(self.model.assigned().values())
        return assigned + [u for u in self.model.devices if u not in assigned]

    def refresh(self) -> None:
        d = self.model.draft
        if [self.site_combo.itemText(i) for i in range(self.site_combo.count())] != list(d.sites):
            current = self.site_combo.currentText()
            self.site_combo.blockSignals(True)
            self.site_combo.clear()
            self.site_combo.addItems(list(d.sites))
            if current in d.sites:
                self.site_combo.setCurrentText(current)
            self.site_combo.blockSignals(False)
        highlight = self.identification.site if self.identification else None
        self.figure.set_state(d.sites, self.model.assigned(), self.alarm_sites, highlight, d.insoles)
        urls = self.urls()
        if d.insoles and d.insoles_url and d.insoles_url not in urls:
            urls.append(d.insoles_url)
        if self.table.rowCount() != len(urls):
            self.table.setRowCount(len(urls))
        for r, url in enumerate(urls):
            self._fill_row(r, url)

    def _fill_row(self, r: int, url: str) -> None:
        d = self.model.draft
        dev = self.model.devices.get(url)
        site = self.model.site_of(url) or ("insoles" if d.insoles and url == d.insoles_url else "")
        live = self.live_rows.get(url)
        chk = self.checked.get(url)
        speed = self.speeds.get(url)
        state = ""
        if live is not None:
            state = live.state
            vals = [fmt(live.rate_hz, ".0f", " Hz"), fmt(live.loss_pct, ".1f", " %"),
                    fmt(live.battery, ".0f", " %"), fmt(live.last_seen_s, ".1f", " s")]
        elif chk is not None:
            state = "ok" if not chk["problems"] else "; ".join(chk["problems"])
            sent = chk["samples"] + chk["lost_packets"]
            vals = [fmt(chk["rate_hz"], ".0f", " Hz"), fmt(100 * chk["lost_packets"] / sent if sent else None,
                                                          ".1f", " %"), fmt(chk["battery_pct"], ".0f", " %"), "–"]
        else:
            vals = ["–", "–", "–", "–"]
        cells = [url, dev.what if dev else "", site, state, *vals,
                 "" if speed is None else f"{speed:.0f} °/s"]
        colour = None
        if live is not None:
            colour = STATE_COLOURS.get(live.state)
        elif chk is not None:
            colour = STATE_COLOURS["ok" if not chk["problems"] else "problem"]
        ident = self.identification
        if ident is not None and ident.leader == url:
            colour = STATE_COLOURS["moving"]
        for c, text in enumerate(cells):
            item = self.table.item(r, c)
            if item is None:
                item = QtWidgets.QTableWidgetItem()
                self.table.setItem(r, c, item)
            if item.text() != text:
                item.setText(text)
                if c == 3:
                    item.setToolTip(text)
            brush = QtGui.QBrush(colour) if colour is not None else QtGui.QBrush()
            if item.background() != brush:
                item.setBackground(brush)

    def row_of(self, url: str) -> int:
        for r in range(self.table.rowCount()):
            item = self.table.item(r, 0)
            if item is not None and item.text() == url:
                return r
        return -1

    def showEvent(self, event: QtGui.QShowEvent) -> None:  # noqa: N802 (Qt's name)
        self.refresh()  # rows were not redrawn while the tab was hidden
        super().showEvent(event)

    def show_live(self, rows: list[DeviceRow], redraw: bool = True) -> None:
        self.live_rows = {r.url: r for r in rows}
        self.alarm_sites = {r.name for r in rows if r.state in ("reconnecting", "silent")}
        if redraw:
            self.refresh()

    def set_session_running(self, on: bool) -> None:
        """Devices in use by a capture cannot be opened a second time for identification."""
        self.session_running = on
        if on:
            self.cancel_identification()
        else:
            self.live_rows = {}
            self.alarm_sites = set()
        for w in (self.identify_button, self.check_button, self.sim_button):
            w.setEnabled(not on)
        self.refresh()

    # ------------------------------------------------------------------ adding and assigning
    def _add_typed(self) -> None:
        from app.capture.setup_file import url_problem

        url = self.url_edit.text().strip()
        if not url:
            return
        problem = url_problem(url, "imu")
        if problem is not None and url_problem(url, "insoles") is not None:
            self.report(f"{problem[0]}; {problem[1]}", "error")
            return
        self.model.add_device(url, "", "added")
        self.url_edit.clear()

    def add_url(self, url: str, what: str = "") -> None:
        self.model.add_device(url, what, "added")

    def select_url(self, url: str) -> None:
        r = self.row_of(url)
        if r >= 0:
            self.table.selectRow(r)

    def assign_selected(self) -> None:
        rows = self.table.selectionModel().selectedRows()
        site = self.site_combo.currentText()
        if not rows or not site:
            self.report("select a device in the list and a site, then Assign", "warning")
            return
        url = self.table.item(rows[0].row(), 0).text()
        self.model.assign(site, url)
        self.report(f"{site}: {url}", "ok")

    def _site_clicked(self, site: str) -> None:
        if site in self.model.draft.sites:
            self.site_combo.setCurrentText(site)

    # ------------------------------------------------------------------ scan and check (worker threads)
    def scan(self) -> None:
        from app.capture.discovery import discover

        self.scan_button.setEnabled(False)
        self.jobs.run("scan", discover, on_done=self._scanned, on_error=self._scan_failed)

    def _scanned(self, found: list[dict]) -> None:
        self.scan_button.setEnabled(True)
        n = 0
        for f in found:
            if f.get("url"):
                self.model.add_device(f["url"], f.get("what", ""), "discovered")
                n += 1
        self.report(f"found {n} device(s) that can be opened" if n else
                    "no devices found (serial, HID, USB, CAN): add one by URL, or simulate", "info")

    def _scan_failed(self, exc: BaseException) -> None:
        self.scan_button.setEnabled(True)
        self.report(f"scan failed: {exc}", "error")

    def check(self) -> None:
        from app.capture.check import check_setup
        from app.capture.setup_file import SetupError

        try:
            setup = self.model.to_setup()
        except SetupError as exc:
            self.report(str(exc), "error")
            return
        self.check_button.setEnabled(False)
        self.report("checking every device for 3 s…", "info")
        self.jobs.run("check", check_setup, setup, 3.0, on_done=self._checked, on_error=self._check_failed)

    def _checked(self, result) -> None:
        self.check_button.setEnabled(not self.session_running)
        self.checked = {d.url: d.as_json() for d in result.devices}
        problems = [f"{d.name}: {'; '.join(d.problems)}" for d in result.devices if d.problems]
        problems += result.problems
        if problems:
            self.report("check: " + " | ".join(problems), "warning")
        else:
            self.report("every device answers at its rate", "ok")
        self.refresh()

    def _check_failed(self, exc: BaseException) -> None:
        self.check_button.setEnabled(not self.session_running)
        self.report(f"check failed: {exc}", "error")

    # ------------------------------------------------------------------ move the sensor you want
    def _identify_clicked(self) -> None:
        if self.identification is not None:
            self.cancel_identification()
            return
        site = self.site_combo.currentText()
        if not site:
            self.report("choose the sites first (Setup), then the site to identify", "warning")
            return
        self.identify(site)

    def identify(self, site: str) -> None:
        urls = [u for u in self.urls() if u != self.model.draft.insoles_url]
        if not urls:
            self.report("no devices to listen to: scan, add one by URL, or simulate", "warning")
            return
        watcher = MotionWatcher(urls, clock=time.monotonic)
        errors: list[str] = []
        readers = DeviceReaders(urls, watcher, on_error=lambda u, why: errors.append(f"{u}: {why}"))
        readers.start()  # each device opens on its own thread
        self.identification = Identification(site, urls, watcher, readers, time.monotonic(), errors=errors)
        self.identify_button.setText("Cancel")
        self.identify_label.setText(f"<b>Move the sensor for {site}</b> (turn it in your hand); "
                                    f"listening to {len(urls)} device(s)…")
        self.refresh()

    def cancel_identification(self, message: str | None = None) -> None:
        ident, self.identification = self.identification, None
        if ident is None:
            return
        self.jobs.run("identify-stop", ident.readers.stop)  # joins the reader threads
        self.speeds = {}
        self.identify_button.setText("Move the sensor you want…")
        self.identify_label.setText(message or "")
        self.refresh()

    def _tick(self) -> None:
        ident = self.identification
        if ident is None:
            return
        self.speeds = ident.watcher.speeds()
        winner = ident.watcher.moving()
        now = time.monotonic()
        if winner != ident.leader:
            ident.leader, ident.leading_since = winner, now
        if winner is not None and ident.leading_since is not None and now - ident.leading_since >= HOLD_S:
            previous = self.model.site_of(winner)
            self.model.assign(ident.site, winner)
            moved = f" (was on {previous})" if previous and previous != ident.site else ""
            self.report(f"{ident.site}: {winner}{moved}", "ok")
            self.cancel_identification(f"{ident.site} is {winner}")
            return
        if ident.readers.all_failed() and now - ident.started > 1.0:
            self.report("no device could be opened: " + "; ".join(ident.errors[:3]), "error")
            self.cancel_identification()
            return
        if now - ident.started > 60.0:
            self.cancel_identification(f"no sensor was moved for {ident.site}")
            return
        self.refresh()
