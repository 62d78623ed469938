"""The setup file: who is captured, which device sits at which sensor site, the insoles,
the model and the calibration protocol, in one human-edited TOML file.

Why TOML read with the standard library and written by hand here: the file is meant to
be edited in any text editor next to the sensors, so it must stay readable and keep its
explanatory comments, and it must not cost a dependency. Why so much care about error
messages: the person reading them is standing in a lab with a subject waiting, so every
error is one line that says where (file and line) and what to do.
"""

from __future__ import annotations

import difflib
import os
import re
import tempfile
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.capture.setup_lines import Locator
from app.capture.setup_tracked import TrackedEntry, parse_tracked
from drivers.urls import DeviceURL
from inference.body.skeleton import SITES

HEIGHT_RANGE_M = (0.5, 2.5)
CALIBRATION_PROTOCOLS: dict[str, str] = {
    "walk": "no table: N-pose, then a few steps forward",
    "table": "sensors on a table, then T-pose",
}
# the live default: the 21-frame file, or the full model where a worn thigh has no shank below it
# (inference.poser.models.model_for_sites)
DEFAULT_MODEL = "auto"
DEFAULT_RECORDINGS = Path("recordings")
# the tables a setup file may hold and the keys each takes ([sensors] takes site names)
TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "subject": ("id", "height", "notes"),
    "sensors": SITES,
    "insoles": ("url",),
    "tracked": (),  # name = URL of a VR rig (any name that is not a site): its sites come from the URL
    "model": ("name", "steps", "confidence", "reach"),
    "calibration": ("protocol",),
    "recording": ("folder",),
}
SENSOR_KEYS = ("url", "serial", "label")
URL_EXAMPLES: dict[str, str] = {
    "xbus": "xbus:///dev/ttyUSB0?baud=115200",
    "bno08x-rvc": "bno08x-rvc:///dev/ttyUSB1",
    "xsens-can": "xsens-can://socketcan/can0?id_offset=0x100",
    "dualsense": "dualsense://",
    "moticon-udp": "moticon-udp://127.0.0.1:9999",
    "vmc-in": "vmc-in://127.0.0.1:39540?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL",
}


class SetupError(ValueError):
    """A problem with a setup file, as ONE line: ``<file>:<line>: <problem>; <what to do>``."""

    def __init__(self, problem: str, fix: str, path: Path | None = None, line: int | None = None) -> None:
        self.problem, self.fix = _one_line(problem), _one_line(fix)
        self.path, self.line = path, line
        super().__init__(str(self))

    def __str__(self) -> str:
        where = str(self.path) if self.path is not None else "<setup>"
        if self.line is not None:
            where += f":{self.line}"
        return f"{where}: {self.problem}; {self.fix}"


@dataclass
class SensorEntry:
    site: str
    url: str
    serial: str | None = None
    label: str | None = None
    line: int | None = field(default=None, compare=False)  # where it was written, for later messages


@dataclass
class Subject:
    id: str
    height_m: float
    notes: str = ""


@dataclass
class Setup:
    subject: Subject
    sensors: dict[str, SensorEntry]
    insoles: str | None = None
    model: str = DEFAULT_MODEL
    steps: str | None = None
    confidence: bool = False  # each pose with its per-segment spread (docs/confidence.md)
    reach: bool = True  # a VR rig's tracked hands: the arms reach the controllers (docs/vr_input.md)
    calibration: str = "walk"
    # relative = relative to the setup file's folder; load_setup resolves it against that folder
    recordings: Path = DEFAULT_RECORDINGS
    path: Path | None = None
    tracked: dict[str, TrackedEntry] = field(default_factory=dict)

    def sites(self) -> tuple[str, ...]:
        """The model's sites the devices observe, in the order the hub's frames hold them:
        the IMU sites, then each tracked device's sites."""
        return tuple(self.sensors) + tuple(s for e in self.tracked.values() for s in e.sites)

    def urls(self) -> dict[str, str]:
        """Every device to open, by name: the sites, the tracked devices, then ``insoles``
        when there are some."""
        out = {site: e.url for site, e in self.sensors.items()}
        out.update({name: e.url for name, e in self.tracked.items()})
        if self.insoles:
            out["insoles"] = self.insoles
        return out

    def recordings_dir(self) -> Path:
        """Where recordings go, whether or not this setup came from a file."""
        if self.recordings.is_absolute() or self.path is None:
            return self.recordings
        return self.path.parent / self.recordings


# ------------------------------------------------------------------------------------ reading
def load_setup(path: str | os.PathLike) -> Setup:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # a BOM from a Windows editor is not an error
    except FileNotFoundError:
        raise SetupError("no such file", "check the path, or write one with `imucap setup new FILE`", p) from None
    except UnicodeDecodeError as exc:
        raise SetupError(f"not a text file ({exc.reason})", "give a TOML setup file", p) from None
    except OSError as exc:
        raise SetupError(f"cannot read it ({exc.strerror})", "check the path and its permissions", p) from None
    return parse_setup(text, p)


def parse_setup(text: str, path: Path | None = None) -> Setup:
    return _Parser(text, Path(path) if path is not None else None).parse()


def url_problem(url: Any, kind: str = "imu") -> tuple[str, str] | None:
    """(problem, what to do) when ``url`` cannot name a device of ``kind`` ("imu",
    "insoles" or "tracked"), else None. Checks only what the URL says; nothing is opened, so a setup
    can be checked on a laptop away from the sensors."""
    import drivers

    if not isinstance(url, str) or not url.strip():
        return "no device URL", f"give one in quotes, e.g. \"{URL_EXAMPLES['xbus']}\""
    if "://" not in url:
        return f"{url!r} is not a device URL", f"write scheme://..., e.g. \"{_example_for(kind)}\""
    try:
        u = drivers.parse_url(url)
    except ValueError as exc:  # e.g. an unclosed [ in the host part
        return f"{url!r} is not a device URL ({exc})", f"write it like \"{_example_for(kind)}\""
    if u.scheme not in drivers.SCHEMES:
        close = difflib.get_close_matches(u.scheme, drivers.SCHEMES, n=1, cutoff=0.5)
        hint = f"did you mean {close[0]}? " if close else ""
        return (f"unknown device scheme {u.scheme!r} in {url!r}",
                f"{hint}use one of {', '.join(drivers.SCHEMES)} (e.g. {_example_for(kind)})")
    missing = _missing_part(u)
    if missing:
        return f"{url!r} names no {missing}", f"write it like {URL_EXAMPLES[u.scheme]}"
    try:
        device = drivers.make_device(url)  # builds the driver object only: nothing is opened
    except (ValueError, TypeError) as exc:
        return f"{url!r}: {exc}", f"fix the URL, e.g. {URL_EXAMPLES[u.scheme]}"
    if device.kind != kind:
        if device.kind == "tracked":
            return (f"{url!r} is a VR rig (tracked points), not {'insoles' if kind == 'insoles' else 'an IMU'}",
                    'put it under [tracked] as vr = "..."')
        if kind == "tracked":
            return (f"{url!r} is not a VR rig", f"a rig is {URL_EXAMPLES['vmc-in']}; put IMUs under [sensors]")
        if kind == "insoles":
            return (f"{url!r} is an IMU, not insoles",
                    f"insoles are {URL_EXAMPLES['moticon-udp']}; put IMUs under [sensors]")
        return f"{url!r} names insoles, not an IMU", "put it under [insoles] as url = \"...\""
    return None


def device_identity(url: str) -> tuple[Any, ...]:
    """What makes two URLs the same physical device: the port, bus address or socket, not
    the parameters (``?id=`` or ``?baud=`` do not make a second sensor)."""
    from drivers import parse_url

    u = parse_url(url)
    if u.scheme in ("xbus", "bno08x-rvc"):
        return ("serial-port", os.path.normpath(u.netloc + u.path))
    if u.scheme == "xsens-can":
        try:
            offset = u.get_int("id_offset", 0)
        except ValueError:
            offset = u.get("id_offset")
        return (u.scheme, u.netloc, u.path.strip("/"), offset)
    if u.scheme == "dualsense":
        return (u.scheme, u.netloc, os.path.normpath(u.path) if u.path else "", u.get("serial"))
    return (u.scheme, u.netloc.lower(), u.path)


def _missing_part(u: DeviceURL) -> str | None:
    if u.scheme in ("xbus", "bno08x-rvc"):
        return None if (u.netloc + u.path) else "serial port"
    if u.scheme == "xsens-can":
        return None if u.netloc and u.path.strip("/") else "CAN interface and channel"
    if u.scheme == "moticon-udp":
        host, _, port = u.netloc.rpartition(":")
        return None if host and port.isdigit() else "host:port"
    if u.scheme == "dualsense" and u.netloc == "unix" and not u.path:
        return "socket path"
    return None


def _example_for(kind: str) -> str:
    return URL_EXAMPLES[{"insoles": "moticon-udp", "tracked": "vmc-in"}.get(kind, "xbus")]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def closest_name(word: str, choices: tuple[str, ...] | list[str]) -> str | None:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return close[0] if close else None


class _Parser:
    """Turns the TOML document into a Setup, raising the first problem as a SetupError."""

    def __init__(self, text: str, path: Path | None) -> None:
        self.text, self.path = text, path
        self.where = Locator(text)

    def error(self, problem: str, fix: str, line: int | None) -> SetupError:
        return SetupError(problem, fix, self.path, line)

    def line(self, table: str, key: str | None = None, sub: str | None = None) -> int | None:
        return self.where.line_of((table,), key, sub)

    def parse(self) -> Setup:
        data = self._load()
        self._tables = {k for k, v in data.items() if isinstance(v, dict) and v}
        self._check_layout(data)
        subject = self._subject(data.get("subject"))
        sensors = self._sensors(data.get("sensors"))
        insoles = self._insoles(data.get("insoles"))
        tracked = self._tracked(data.get("tracked"), sensors)
        self._check_one_device_per_site(sensors, insoles, tracked)
        model, steps = self._model(data.get("model", {}))
        return Setup(subject=subject, sensors=sensors, insoles=insoles, tracked=tracked, model=model, steps=steps,
                     confidence=self._flag(data.get("model", {}), "confidence", False),
                     reach=self._flag(data.get("model", {}), "reach", True),
                     calibration=self._calibration(data.get("calibration", {})),
                     recordings=self._recordings(data.get("recording", {})), path=self.path)

    # --- the document --------------------------------------------------------------------------
    def _load(self) -> dict[str, Any]:
        try:
            return tomllib.loads(self.text)
        except tomllib.TOMLDecodeError as exc:
            raise self._decode_error(str(exc)) from None

    def _decode_error(self, message: str) -> SetupError:
        m = re.match(r"(.*?)\s*\(at (?:line (\d+), column \d+|end of document)\)\s*$", message)
        what, line = (m.group(1), int(m.group(2)) if m.group(2) else None) if m else (message, None)
        if line is None:
            line = max(1, self.text.count("\n") + (0 if self.text.endswith("\n") else 1))
        dup = self.where.duplicate_at(line) if what.startswith(("Cannot overwrite", "Cannot declare")) else None
        if dup is None and what.startswith(("Cannot overwrite", "Cannot declare")):
            dup = self.where.first_duplicate()
        if dup is not None:
            return self._duplicate_error(*dup)
        return self.error(f"TOML syntax error: {what}",
                          'fix that line (text in quotes: key = "value"; tables as [name])', line)

    def _duplicate_error(self, table: tuple[str, ...], key: str | None, lines: list[int]) -> SetupError:
        first, second = lines[0], lines[1]
        if key is None:
            return self.error(f"table [{'.'.join(table)}] appears twice (lines {first} and {second})",
                              "merge them into one", second)
        if table == ("sensors",):
            return self.error(f"site {key} given twice (lines {first} and {second})",
                              "keep one of them: a site carries one sensor", second)
        name = f"[{'.'.join(table)}]" if table else "the top level"
        return self.error(f"{key} given twice in {name} (lines {first} and {second})", "keep one of them", second)

    def _check_layout(self, data: dict[str, Any]) -> None:
        tables = tuple(TABLE_KEYS)
        for name, value in data.items():
            if name not in TABLE_KEYS:
                close = closest_name(name, tables)
                hint = f"did you mean [{close}]? " if close else ""
                kind = "table" if isinstance(value, dict) else "key"
                shown = f"[{name}]" if kind == "table" else repr(name)
                raise self.error(f"unknown {kind} {shown}", f"{hint}tables are: {', '.join(tables)}",
                                 self.where.line_of((), name))
            if not isinstance(value, dict):
                raise self.error(f"{name} must be a table", f"write it as [{name}] followed by key = value lines",
                                 self.where.line_of((), name))
            if name not in ("sensors", "tracked"):
                self._check_keys(name, value, TABLE_KEYS[name])

    def _check_keys(self, table: str, value: dict[str, Any], allowed: tuple[str, ...]) -> None:
        for key in value:
            if key not in allowed:
                close = closest_name(key, allowed)
                hint = f"did you mean {close}? " if close else ""
                raise self.error(f"unknown key {key!r} in [{table}]", f"{hint}keys there: {', '.join(allowed)}",
                                 self.line(table, key))

    def _text(self, table: str, key: str, value: Any, line: int | None = None) -> str:
        if not isinstance(value, str):
            raise self.error(f"{key} in [{table}] must be text", f'put it in quotes: {key} = "..."',
                             line or self.line(table, key))
        return value

    # --- tables ---------------------------------------------------------------------------------
    def _subject(self, table: dict[str, Any] | None) -> Subject:
        if table is None:
            raise self.error("no [subject] table", 'add [subject] with id = "P01" and height = 1.75 (metres)', None)
        head = self.line("subject")
        if "id" not in table:
            raise self.error("the subject has no id", 'add id = "P01" under [subject]', head)
        sid = self._text("subject", "id", table["id"]).strip()
        if not sid:
            raise self.error("the subject id is empty", 'give one, e.g. id = "P01"', self.line("subject", "id"))
        notes = self._text("subject", "notes", table.get("notes", ""))
        return Subject(sid, self._height(table, head), notes)

    def _height(self, table: dict[str, Any], head: int | None) -> float:
        if "height" not in table:
            raise self.error("the subject's height is missing",
                             "add height = 1.75 (metres) under [subject]: it sets the bone lengths", head)
        h, line = table["height"], self.line("subject", "height")
        if isinstance(h, bool) or not isinstance(h, int | float):
            raise self.error(f"height {h!r} is not a number", "write metres without quotes, e.g. height = 1.75", line)
        lo, hi = HEIGHT_RANGE_M
        if not lo <= h <= hi:
            fix = f"give metres between {lo} and {hi}"
            if 50 <= h <= 250:
                fix += f" ({h:g} cm is height = {h / 100:.2f})"
            raise self.error(f"height {h:g} m is not a body height", fix, line)
        return float(h)

    def _sensors(self, table: dict[str, Any] | None) -> dict[str, SensorEntry]:
        example = f'pelvis = "{URL_EXAMPLES["xbus"]}"'
        if not table and "tracked" in self._tables:
            return {}  # a VR rig alone observes sites too
        if not table:
            raise self.error("no sensors", f"add a [sensors] table with site = device URL lines, e.g. {example}",
                             self.line("sensors"))
        entries: dict[str, SensorEntry] = {}
        for site, value in table.items():
            line = self.line("sensors", site)
            if site not in SITES:
                close = closest_name(site, SITES)
                hint = f"did you mean {close}? " if close else ""
                raise self.error(f"unknown site {site!r}", f"{hint}sites are: {', '.join(SITES)}", line)
            entries[site] = self._sensor(site, value, line)
        return {s: entries[s] for s in SITES if s in entries}

    def _sensor(self, site: str, value: Any, line: int | None) -> SensorEntry:
        if isinstance(value, str):
            entry = SensorEntry(site, value, line=line)
        elif isinstance(value, dict):
            for key in value:
                if key not in SENSOR_KEYS:
                    close = closest_name(key, SENSOR_KEYS)
                    hint = f"did you mean {close}? " if close else ""
                    raise self.error(f"unknown key {key!r} for sensor {site}",
                                     f"{hint}a sensor takes {', '.join(SENSOR_KEYS)}", line)
            if "url" not in value:
                raise self.error(f"sensor {site} has no url", f'write {site} = {{ url = "{URL_EXAMPLES["xbus"]}" }}',
                                 line)
            url = self._text("sensors", "url", value["url"], line)
            serial = None if value.get("serial") is None else self._text("sensors", "serial", value["serial"], line)
            label = None if value.get("label") is None else self._text("sensors", "label", value["label"], line)
            entry = SensorEntry(site, url, serial or None, label or None, line=line)
        else:
            raise self.error(f"sensor {site} must be a device URL in quotes",
                             f'write {site} = "{URL_EXAMPLES["xbus"]}", or {{ url = "...", label = "..." }}', line)
        problem = url_problem(entry.url, "imu")
        if problem is not None:
            raise self.error(f"{site}: {problem[0]}", problem[1], line)
        return entry

    def _insoles(self, table: dict[str, Any] | None) -> str | None:
        if table is None:
            return None
        if "url" not in table:
            raise self.error("[insoles] has no url",
                             f'add url = "{URL_EXAMPLES["moticon-udp"]}", or delete the table', self.line("insoles"))
        url = self._text("insoles", "url", table["url"]).strip()
        if not url:
            return None  # url = "" reads as "no insoles", so the table can stay as a template
        problem = url_problem(url, "insoles")
        if problem is not None:
            raise self.error(f"insoles: {problem[0]}", problem[1], self.line("insoles", "url"))
        return url

    def _tracked(self, table: dict[str, Any] | None, sensors: dict[str, SensorEntry]) -> dict[str, TrackedEntry]:
        return parse_tracked(self, table, sensors, url_problem, URL_EXAMPLES["vmc-in"])

    def _check_one_device_per_site(self, sensors: dict[str, SensorEntry], insoles: str | None,
                                   tracked: dict[str, TrackedEntry] | None = None) -> None:
        named = [(e.site, e.url, e.line) for e in sensors.values()]
        named += [(e.name, e.url, e.line) for e in (tracked or {}).values()]
        if insoles:
            named.append(("insoles", insoles, self.line("insoles", "url")))
        named.sort(key=lambda n: n[2] or 0)
        seen: dict[tuple[Any, ...], tuple[str, int | None]] = {}
        for name, url, line in named:
            key = device_identity(url)
            if key in seen:
                other, other_line = seen[key]
                raise self.error(f"one device is given for two sites: {other} (line {other_line}) and {name} "
                                 f"(line {line}) both use {url!r}",
                                 "give each site its own sensor (`imucap devices identify` tells them apart)", line)
            seen[key] = (name, line)
        serials: dict[str, SensorEntry] = {}
        for e in sorted(sensors.values(), key=lambda e: e.line or 0):
            if e.serial and e.serial in serials:
                o = serials[e.serial]
                raise self.error(f"serial {e.serial} is given for {o.site} (line {o.line}) and {e.site} "
                                 f"(line {e.line})", "a sensor has one serial: check the label on each", e.line)
            if e.serial:
                serials[e.serial] = e

    def _model(self, table: dict[str, Any]) -> tuple[str, str | None]:
        name = self._text("model", "name", table.get("name", DEFAULT_MODEL)).strip()
        if not name:
            raise self.error("the model name is empty",
                             'use "auto", "diffusion", "fast", "regressor", "floor" or a model file',
                             self.line("model", "name"))
        steps = table.get("steps")
        if steps is None:
            return name, None
        line = self.line("model", "steps")
        if isinstance(steps, bool) or not isinstance(steps, str | int):
            raise self.error(f"steps {steps!r} is not a step list", 'write e.g. steps = "10D:3"', line)
        steps = str(steps).strip()
        from inference.model.diffusion import parse_steps

        try:
            parse_steps(steps)
        except (ValueError, TypeError) as exc:
            why = "" if "literal" in str(exc) else f" ({exc})"
            raise self.error(f"steps {steps!r} is not a step list{why}",
                             'write e.g. "10D:3", "paper", a number of steps, or a list "1000,500,0"', line) from None
        return name, steps

    def _flag(self, table: dict[str, Any], key: str, default: bool) -> bool:
        value = table.get(key, default)
        if not isinstance(value, bool):
            raise self.error(f"{key} {value!r} is not true or false", f"write {key} = true (or false)",
                             self.line("model", key))
        return value

    def _calibration(self, table: dict[str, Any]) -> str:
        protocol = self._text("calibration", "protocol", table.get("protocol", "walk")).strip()
        if protocol not in CALIBRATION_PROTOCOLS:
            choices = " or ".join(f'"{k}" ({v})' for k, v in CALIBRATION_PROTOCOLS.items())
            raise self.error(f"unknown calibration protocol {protocol!r}", f"use {choices}",
                             self.line("calibration", "protocol"))
        return protocol

    def _recordings(self, table: dict[str, Any]) -> Path:
        folder = self._text("recording", "folder", table.get("folder", str(DEFAULT_RECORDINGS))).strip()
        if not folder:
            raise self.error("the recording folder is empty", 'give one, e.g. folder = "recordings"',
                             self.line("recording", "folder"))
        p = Path(folder).expanduser()
        return p if p.is_absolute() or self.path is None else self.path.parent / p


# ------------------------------------------------------------------------------------ writing
def dump_setup(setup: Setup) -> str:
    """The file text, with a comment on each table for whoever edits it next."""
    return _dump(setup, setup.path.parent if setup.path is not None else None)


def save_setup(setup: Setup, path: str | os.PathLike) -> None:
    """Write atomically: a crash or a full disk leaves the old file whole, never half of one."""
    target = Path(path)
    text = _dump(setup, target.parent)
    folder = target.parent if str(target.parent) else Path(".")
    mode = (target.stat().st_mode & 0o777) if target.exists() else 0o644
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _quote(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _sensor_value(e: SensorEntry) -> str:
    if e.serial is None and e.label is None:
        return _quote(e.url)
    items = [f"url = {_quote(e.url)}"]
    if e.serial is not None:
        items.append(f"serial = {_quote(e.serial)}")
    if e.label is not None:
        items.append(f"label = {_quote(e.label)}")
    return "{ " + ", ".join(items) + " }"


def _folder_text(recordings: Path, base: Path | None) -> str:
    if base is not None and recordings.is_absolute() == base.is_absolute():
        try:
            return recordings.relative_to(base).as_posix()
        except ValueError:
            pass
    return recordings.as_posix()


def _dump(setup: Setup, base: Path | None) -> str:
    s = setup.subject
    width = max((len(site) for site in setup.sensors), default=0)
    lines = [
        "# imucap setup: who is captured and which device sits at which sensor site.",
        "# Check it with `imucap setup check FILE`; capture with `imucap capture --setup FILE`.",
        "",
        "[subject]",
        "# id names the person in recordings; height (metres) sets the bone lengths",
        f"id = {_quote(s.id)}",
        f"height = {float(s.height_m)!r}",
        f"notes = {_quote(s.notes)}",
        "",
        "[sensors]",
        '# site = "device URL", or site = { url = "...", serial = "...", label = "blue strap" }',
        f"# sites: {', '.join(SITES)}",
        f"# URLs: {', '.join(URL_EXAMPLES[k] for k in ('xbus', 'bno08x-rvc', 'xsens-can', 'dualsense'))}",
    ]
    lines += [f"{site.ljust(width)} = {_sensor_value(e)}" for site, e in setup.sensors.items()]
    if setup.tracked:
        lines += ["", "[tracked]", "# a VR rig: name = \"vmc-in://HOST:PORT?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL\"",
                  "# (controllers stand for the wrists' sites; a site is given once, here or under [sensors])"]
        lines += [f"{name} = {_quote(e.url)}" for name, e in setup.tracked.items()]
    lines += ["", "# pressure insoles streaming to this host:port (Moticon); delete the table when there are none"]
    if setup.insoles:
        lines += ["[insoles]", f"url = {_quote(setup.insoles)}"]
    else:
        lines += ["# [insoles]", f'# url = "{URL_EXAMPLES["moticon-udp"]}"']
    lines += [
        "",
        "[model]",
        '# name: "auto" (the default: "fast", or "diffusion" where a thigh is worn without its shank),',
        '#   "diffusion" (the full model, three times the compute), "fast", "regressor", "floor" (no model)',
        '#   or a model file;',
        '# steps: diffusion steps, e.g. "10D:3" (fewer = faster); leave out for the model\'s own',
        f"name = {_quote(setup.model)}",
        f"steps = {_quote(setup.steps)}" if setup.steps is not None else '# steps = "10D:3"',
        "# confidence: each pose with how sure the model is of each segment (~40 % more per frame)",
        f"confidence = {'true' if setup.confidence else 'false'}",
        *(["# reach: the arms of the hands a VR rig tracks reach its controllers",
           f"reach = {'true' if setup.reach else 'false'}"] if setup.tracked else []),
        "",
        "[calibration]",
        "# " + "; ".join(f'"{k}": {v}' for k, v in CALIBRATION_PROTOCOLS.items()),
        f"protocol = {_quote(setup.calibration)}",
        "",
        "[recording]",
        "# where recordings go; a relative folder is relative to this file's folder",
        f"folder = {_quote(_folder_text(setup.recordings, base))}",
        "",
    ]
    return "\n".join(lines)
