"""The setup being edited in the window, shared by the setup and devices panels.

Why a draft beside ``Setup``: a ``Setup`` is only valid once every chosen site has a
device, but a clinician chooses the sites first and assigns devices later, toggles a
site off and on again, and expects the device it had to come back. The draft holds all
of that; ``to_setup`` turns it into the file's format and says what is still missing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from PySide6 import QtCore

from app.capture.setup_file import (
    DEFAULT_MODEL,
    DEFAULT_RECORDINGS,
    URL_EXAMPLES,
    SensorEntry,
    Setup,
    SetupError,
    Subject,
    url_problem,
)
from inference.body.skeleton import SITES


@dataclass
class KnownDevice:
    """A device the window can offer: found by a scan, typed in, simulated, or from a file."""

    url: str
    what: str = ""
    source: str = "added"  # discovered, added, simulated, setup


@dataclass
class SetupDraft:
    subject_id: str = "P01"
    height_m: float = 1.75
    notes: str = ""
    sites: tuple[str, ...] = ()
    urls: dict[str, str] = field(default_factory=dict)  # kept for sites toggled off, so they come back
    labels: dict[str, str] = field(default_factory=dict)
    insoles: bool = False
    insoles_url: str = URL_EXAMPLES["moticon-udp"]
    model: str = DEFAULT_MODEL
    steps: str | None = None
    calibration: str = "walk"
    recordings: Path = DEFAULT_RECORDINGS
    path: Path | None = None


class SetupModel(QtCore.QObject):
    """The draft plus the devices on offer; ``changed`` after every edit, so each panel
    redraws from one source of truth instead of keeping copies in step."""

    changed = QtCore.Signal()

    def __init__(self, parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.draft = SetupDraft()
        self.devices: dict[str, KnownDevice] = {}

    # ------------------------------------------------------------------ from and to files
    def load(self, setup: Setup) -> None:
        d = SetupDraft(subject_id=setup.subject.id, height_m=setup.subject.height_m, notes=setup.subject.notes,
                       sites=tuple(setup.sensors), urls={s: e.url for s, e in setup.sensors.items()},
                       labels={s: e.label for s, e in setup.sensors.items() if e.label},
                       insoles=setup.insoles is not None, model=setup.model, steps=setup.steps,
                       calibration=setup.calibration, recordings=setup.recordings, path=setup.path)
        if setup.insoles:
            d.insoles_url = setup.insoles
        self.draft = d
        for e in setup.sensors.values():
            self.devices.setdefault(e.url, KnownDevice(e.url, e.label or "", "setup"))
        self.changed.emit()

    def to_setup(self) -> Setup:
        """The draft as a Setup; a SetupError naming what is missing (sites without a
        device, a bad URL, a height out of range) when it cannot be one yet."""
        d = self.draft
        where = d.path
        if not d.subject_id.strip():
            raise SetupError("the subject has no id", "type one in Subject id", where)
        if not d.sites:
            raise SetupError("no sensor sites chosen", "click sites on the body or pick a preset", where)
        missing = [s for s in d.sites if not d.urls.get(s)]
        if missing:
            raise SetupError(f"no device for {', '.join(missing)}",
                             "assign one in Devices (pick it, or move the sensor you want)", where)
        sensors = {}
        for s in d.sites:
            problem = url_problem(d.urls[s], "imu")
            if problem:
                raise SetupError(f"{s}: {problem[0]}", problem[1], where)
            sensors[s] = SensorEntry(s, d.urls[s], label=d.labels.get(s))
        insoles = d.insoles_url.strip() if d.insoles else None
        if insoles:
            problem = url_problem(insoles, "insoles")
            if problem:
                raise SetupError(f"insoles: {problem[0]}", problem[1], where)
        return Setup(subject=Subject(d.subject_id.strip(), float(d.height_m), d.notes), sensors=sensors,
                     insoles=insoles, model=d.model, steps=d.steps, calibration=d.calibration,
                     recordings=d.recordings, path=d.path)

    # ------------------------------------------------------------------ edits
    def update(self, **fields: object) -> None:
        for k, v in fields.items():
            if not hasattr(self.draft, k):
                raise AttributeError(k)
            setattr(self.draft, k, v)
        self.changed.emit()

    def set_sites(self, sites: tuple[str, ...] | list[str] | set[str]) -> None:
        chosen = set(sites)
        self.draft.sites = tuple(s for s in SITES if s in chosen)
        self.changed.emit()

    def toggle_site(self, site: str) -> None:
        sites = set(self.draft.sites)
        sites.symmetric_difference_update({site})
        self.set_sites(sites)

    def assign(self, site: str, url: str | None) -> None:
        """Put ``url`` on ``site`` (taking it off any other site: one device, one place)
        and choose the site if it was not."""
        if url:
            for s, u in list(self.draft.urls.items()):
                if u == url and s != site:
                    del self.draft.urls[s]
            self.draft.urls[site] = url
            self.devices.setdefault(url, KnownDevice(url))
            if site not in self.draft.sites:
                self.draft.sites = tuple(s for s in SITES if s in set(self.draft.sites) | {site})
        else:
            self.draft.urls.pop(site, None)
        self.changed.emit()

    def add_device(self, url: str, what: str = "", source: str = "added") -> KnownDevice:
        dev = self.devices.get(url)
        if dev is None:
            dev = self.devices[url] = KnownDevice(url, what, source)
        elif what and not dev.what:
            dev.what = what
        self.changed.emit()
        return dev

    def remove_device(self, url: str) -> None:
        self.devices.pop(url, None)
        for s, u in list(self.draft.urls.items()):
            if u == url:
                del self.draft.urls[s]
        self.changed.emit()

    # ------------------------------------------------------------------ questions
    def site_of(self, url: str) -> str | None:
        return next((s for s, u in self.draft.urls.items() if u == url and s in self.draft.sites), None)

    def assigned(self) -> dict[str, str]:
        return {s: self.draft.urls[s] for s in self.draft.sites if self.draft.urls.get(s)}

    def unassigned(self) -> list[str]:
        return [s for s in self.draft.sites if not self.draft.urls.get(s)]
