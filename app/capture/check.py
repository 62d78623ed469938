"""Is every device a setup names there and healthy, before the subject is strapped in?

Each device is opened and read for a few seconds, all in parallel, and what was seen is
turned into plain words a person can act on ("does not answer (check power/cable/URL)",
"rate 12 Hz, expected >= 50"), because the person running it is fixing cables, not
reading counters. Used by ``imucap setup check`` and, later, by the GUI.
"""

from __future__ import annotations

import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from app.capture.setup_file import Setup

MIN_RATE_HZ = {"imu": 50.0, "insoles": 20.0}  # below: the 60 Hz resampler starves (insoles: 20 Hz contacts)
MAX_LOSS = 0.02  # fraction of packets
MAX_CORRUPT = 0.01  # fraction of packets
LOW_BATTERY_PCT = 20.0
NO_ANSWER = "does not answer (check power/cable/URL)"


@dataclass
class DeviceCheck:
    """What one device did during the check, and what is wrong with it in plain words."""

    name: str  # the site, or "insoles"
    url: str
    kind: str = "imu"
    samples: int = 0
    rate_hz: float = 0.0
    errors: int = 0
    lost_packets: int = 0
    disconnects: int = 0
    battery_pct: float | None = None
    serial_expected: str | None = None
    serial_reported: str | None = None
    open_error: str | None = None
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def serial_match(self) -> bool | None:
        if self.serial_expected is None or self.serial_reported is None:
            return None
        return self.serial_expected.strip().lower() == self.serial_reported.strip().lower()

    def as_json(self) -> dict[str, Any]:
        out = asdict(self)
        out.update(ok=self.ok, serial_match=self.serial_match)
        return out


@dataclass
class SetupCheck:
    setup: Setup
    seconds: float
    devices: list[DeviceCheck]
    problems: list[str] = field(default_factory=list)  # the setup's own (a model file that is not there)
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems and all(d.ok for d in self.devices)

    def as_json(self) -> dict[str, Any]:
        s = self.setup
        return {
            "file": None if s.path is None else str(s.path),
            "subject": {"id": s.subject.id, "height_m": s.subject.height_m},
            "seconds": self.seconds,
            "ok": self.ok,
            "devices": {d.name: d.as_json() for d in self.devices},
            "problems": self.problems,
            "warnings": self.warnings,
        }


def check_setup(setup: Setup, seconds: float = 3.0) -> SetupCheck:
    """Open every device of ``setup`` at once, read each for ``seconds``, judge."""
    expected = {site: e.serial for site, e in setup.sensors.items()}
    results: dict[str, DeviceCheck] = {}

    def run(name: str, url: str) -> None:
        kind = "insoles" if name == "insoles" else "imu"
        results[name] = check_device(name, url, seconds, kind=kind, serial=expected.get(name))

    threads = [threading.Thread(target=run, args=item, daemon=True, name=f"check-{item[0]}")
               for item in setup.urls().items()]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    report = SetupCheck(setup, seconds, [results[name] for name in setup.urls()])
    _check_model(setup.model, report, setup.sites())
    _check_recordings(setup.recordings_dir(), report)
    return report


def check_device(name: str, url: str, seconds: float, *, kind: str = "imu", serial: str | None = None) -> DeviceCheck:
    import drivers

    out = DeviceCheck(name, url, kind, serial_expected=serial)
    try:
        dev = drivers.open_device(url)
    except (OSError, ValueError) as exc:
        out.open_error = " ".join(str(exc).split()) or type(exc).__name__
        out.problems.append(f"{NO_ANSWER}: {out.open_error}")
        return out
    first = last = None
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            # never a zero timeout: that means "the selector saw data" to a serial driver, and
            # an empty read then looks like an unplugged port
            for s in dev.read_many(min(0.1, max(0.005, end - time.monotonic()))):
                out.samples += 1
                first = s.t if first is None else first
                last = s.t
                if s.battery is not None:
                    out.battery_pct = float(s.battery)
                if s.extra.get("serial"):
                    out.serial_reported = str(s.extra["serial"])
    except (OSError, ValueError) as exc:  # reconnect=0: the loss ends the check of this device
        out.open_error = " ".join(str(exc).split())
    finally:
        dev.close()
    reported = getattr(dev, "serial", None)
    if isinstance(reported, str) and reported:
        out.serial_reported = reported
    st = dev.stats
    out.errors, out.lost_packets, out.disconnects = st.errors, st.lost_packets, st.disconnects
    if out.samples > 1 and first is not None and last is not None and last > first:
        out.rate_hz = round((out.samples - 1) / (last - first), 1)
    out.problems += judge(out)
    return out


def judge(d: DeviceCheck) -> list[str]:
    """The plain-words problems of what was seen (pure, so each wording is testable)."""
    if d.samples == 0:
        hint = f"{NO_ANSWER}: {d.open_error}" if d.open_error else NO_ANSWER
        if d.kind == "insoles" and not d.open_error:
            hint += "; is the insoles app streaming to this host:port?"
        return [hint]
    problems = []
    need = MIN_RATE_HZ[d.kind]
    if d.rate_hz < need:
        problems.append(f"rate {d.rate_hz:.0f} Hz, expected >= {need:.0f}")
    sent = d.samples + d.lost_packets
    if d.lost_packets and d.lost_packets / sent > MAX_LOSS:
        problems.append(f"lost {d.lost_packets} packets ({100 * d.lost_packets / sent:.0f}%): "
                        "check the cable, or move the receiver closer")
    corrupt = d.errors - d.lost_packets
    if corrupt and corrupt / sent > MAX_CORRUPT:
        problems.append(f"{corrupt} corrupted packets: check the cable and the baud rate")
    if d.disconnects:
        problems.append(f"disconnected {d.disconnects} time(s) during the check: check the cable and the battery")
    if d.battery_pct is not None and d.battery_pct < LOW_BATTERY_PCT:
        problems.append(f"battery {d.battery_pct:.0f}%: charge it before capturing")
    if d.serial_match is False:
        problems.append(f"serial {d.serial_expected} expected, device says {d.serial_reported}: "
                        "another sensor is plugged in here (`imucap devices identify` finds which)")
    return problems


def _check_model(spec: str, report: SetupCheck, sites: tuple[str, ...] | None = None) -> None:
    from inference.poser.models import DEFAULT_WEIGHTS, MODEL_NAMES, model_for_sites

    if spec == "floor":
        return
    spec = str(model_for_sites(spec, sites))  # the live default: the file it chooses for these sensors
    if spec in DEFAULT_WEIGHTS:
        if not DEFAULT_WEIGHTS[spec].exists():
            report.warnings.append(f"model {spec}: the trained weights {DEFAULT_WEIGHTS[spec]} are missing; "
                                   "capture would run the floor baseline")
        return
    if not Path(spec).exists():
        report.problems.append(f"model {spec!r} is not a file and not one of {', '.join(MODEL_NAMES)}; "
                               "fix [model] name in the setup")


def _check_recordings(folder: Path, report: SetupCheck) -> None:
    import os

    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        report.warnings.append(f"recording folder {folder} cannot be created or written; "
                               "fix [recording] folder or its permissions")
