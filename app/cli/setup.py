"""`imucap setup new|check|example FILE`: write a setup file by moving each sensor when asked;
check that every device a setup file names answers, fast enough, before a capture; or
write the simulated suit's setup, for trying imucap without sensors.

    imucap setup new FILE [--url URL ...] [--sites SITE,...] [--seconds-per-site S] [--force]
    imucap setup check FILE [--seconds S] [--json]
    imucap setup example FILE [--force]

`setup new` asks for the subject, then names each site in turn ("move the sensor for
l_wrist now"): the device that moves is put at that site, never twice; Enter skips a
site. Every answer can come from a pipe: each line typed while a site waits skips it,
and when the input ends the sites are still assigned by motion (or time out).
"""

from __future__ import annotations

import argparse
import json
import queue
import sys
import threading
import time
from pathlib import Path
from typing import TextIO

from app.capture.setup_file import HEIGHT_RANGE_M, SensorEntry, Setup, SetupError, Subject

CLASSIC_SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
HOLD_S = 0.3  # a device must lead this long before it is taken: a bump is not a choice


class EndOfInput(Exception):
    """The answers ended (a pipe ran dry, Ctrl-D) before a required one came."""


class Answers:
    """Lines from the standard input, read by a thread: a site waits for motion and for
    Enter at the same time, on terminals and pipes alike."""

    def __init__(self, stream: TextIO) -> None:
        self._lines: queue.Queue[str | None] = queue.Queue()
        self.ended = False
        try:  # piped answers are not echoed by a terminal: echo them, so the transcript reads right
            self.echo = not stream.isatty()
        except (AttributeError, ValueError):
            self.echo = True
        threading.Thread(target=self._read, args=(stream,), daemon=True, name="setup-stdin").start()

    def _read(self, stream: TextIO) -> None:
        for line in iter(stream.readline, ""):
            self._lines.put(line.rstrip("\r\n"))
        self._lines.put(None)

    def ask(self, prompt: str) -> str:
        """The next line, after showing ``prompt``; raises EndOfInput when there is none."""
        print(prompt, end="", flush=True)
        line = None if self.ended else self._lines.get()
        if line is None:
            self.ended = True
            print()
            raise EndOfInput(prompt.strip().rstrip(":"))
        if self.echo:
            print(line)
        return line.strip()

    def poll(self) -> str | None:
        """A line typed since the last look, without waiting; None if there is none."""
        if self.ended:
            return None
        try:
            line = self._lines.get_nowait()
        except queue.Empty:
            return None
        if line is None:
            self.ended = True
        return line


# ------------------------------------------------------------------------------------- new
def ask_subject(answers: Answers) -> Subject:
    sid = ""
    while not sid:
        sid = answers.ask("subject id (e.g. P014): ")
        if not sid:
            print("  an id is needed: it names the subject's recordings")
    height = None
    while height is None:
        height = parse_height(answers.ask("height in metres (e.g. 1.75): "))
        if height is None:
            print(f"  give the height in metres, between {HEIGHT_RANGE_M[0]} and {HEIGHT_RANGE_M[1]}")
    try:
        notes = answers.ask("notes (Enter for none): ")
    except EndOfInput:
        notes = ""
    return Subject(sid, height, notes)


def parse_height(text: str) -> float | None:
    t = text.lower().strip().removesuffix("m").strip()
    try:
        h = float(t.replace(",", "."))
    except ValueError:
        return None
    return h if HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1] else None


def wait_for_site(site: str, candidates: list[str], watcher, answers: Answers, seconds: float) -> str | None:
    """The candidate that is moved while ``site`` is asked for; None when skipped or timed out."""
    print(f"move the sensor for {site} now (Enter to skip)", flush=True)
    end = time.monotonic() + seconds
    leader, since = None, 0.0
    while time.monotonic() < end:
        if answers.poll() is not None:
            print(f"  {site}: skipped", flush=True)
            return None
        now = time.monotonic()
        winner = watcher.moving(among=candidates)
        if winner != leader:
            leader, since = winner, now
        if winner is not None and now - since >= HOLD_S:
            print(f"  {site} -> {winner}", flush=True)
            return winner
        time.sleep(0.05)
    print(f"  {site}: no sensor moved within {seconds:g} s; skipped", flush=True)
    return None


def assign_sites(sites: list[str], urls: list[str], watcher, answers: Answers, seconds: float) -> dict[str, str]:
    assigned: dict[str, str] = {}
    for site in sites:
        candidates = [u for u in urls if u not in assigned.values()]
        if not candidates:
            print(f"every open device has a site; {', '.join(s for s in sites if s not in assigned)} left without one")
            break
        url = wait_for_site(site, candidates, watcher, answers, seconds)
        if url is not None:
            assigned[site] = url
    return assigned


def ask_insoles(answers: Answers, taken: list[str]) -> str | None:
    from app.capture.setup_file import device_identity, url_problem

    used = {device_identity(u) for u in taken}
    while True:
        try:
            url = answers.ask("insoles URL, e.g. moticon-udp://127.0.0.1:9999 (Enter for none): ")
        except EndOfInput:
            return None
        if not url:
            return None
        problem = url_problem(url, "insoles")
        if problem is None and device_identity(url) in used:
            problem = (f"{url} is already a sensor's device", "give the insoles' own host:port")
        if problem is None:
            return url
        print(f"  {problem[0]}; {problem[1]}")


def parse_site_list(text: str | None) -> list[str]:
    from app.capture.setup_file import closest_name
    from inference.body.skeleton import SITES

    if not text:
        return list(CLASSIC_SITES)
    sites = [s.strip() for s in text.split(",") if s.strip()]
    for s in sites:
        if s not in SITES:
            close = closest_name(s, SITES)
            hint = f"did you mean {close}? " if close else ""
            raise ValueError(f"--sites: unknown site {s!r}; {hint}sites are: {', '.join(SITES)}")
    if len(set(sites)) != len(sites):
        raise ValueError("--sites: a site is named twice")
    return sites


def candidate_urls(given: list[str]) -> list[str]:
    from app.capture.setup_file import device_identity, url_problem

    seen: dict[tuple, str] = {}
    for url in given:
        problem = url_problem(url, "imu")
        if problem is not None:
            raise ValueError(f"--url: {problem[0]}; {problem[1]}")
        other = seen.setdefault(device_identity(url), url)
        if other != url:
            raise ValueError(f"--url: {other} and {url} are the same device; give it once")
    if given:
        return list(dict.fromkeys(given))
    from app.cli.devices import discover
    from app.cli.identify import discovered_urls

    return discovered_urls(discover)


def cmd_new(args: argparse.Namespace) -> int:
    path = Path(args.file)
    try:
        refuse = _target_problem(path, args.force)
        if refuse:
            raise ValueError(refuse)
        sites = parse_site_list(args.sites)
        urls = candidate_urls(args.url)
    except ValueError as exc:
        print(f"imucap setup new: {exc}", file=sys.stderr)
        return 2
    if not urls:
        print("imucap setup new: no devices found; connect them, or give each with --url URL", file=sys.stderr)
        return 1
    answers = Answers(sys.stdin)
    try:
        subject = ask_subject(answers)
    except EndOfInput as exc:
        print(f"imucap setup new: the input ended before an answer to '{exc}'; nothing written", file=sys.stderr)
        return 2
    assigned = _assign_with_devices(sites, urls, answers, args.seconds_per_site)
    if assigned is None:
        return 1
    if not assigned:
        print("imucap setup new: no sensor was assigned to a site; nothing written", file=sys.stderr)
        return 1
    insoles = ask_insoles(answers, list(assigned.values()))
    sensors = {s: SensorEntry(s, assigned[s]) for s in sites if s in assigned}
    setup = Setup(subject, sensors, insoles, path=path)
    from app.capture.setup_file import save_setup

    save_setup(setup, path)
    print(f"wrote {path}:\n")
    print(path.read_text(encoding="utf-8"))
    return 0


def cmd_example(args: argparse.Namespace) -> int:
    """The setup of examples/simulated_suit.toml (shipped with the package), which
    ``imucap devices simulate --setup`` serves and ``imucap capture --setup`` reads as it is."""
    from importlib.resources import files

    path = Path(args.file)
    refuse = _target_problem(path, args.force)
    if refuse:
        print(f"imucap setup example: {refuse}", file=sys.stderr)
        return 2
    path.write_text((files("app.capture") / "simulated_suit.toml").read_text(encoding="utf-8"), encoding="utf-8")
    print(f"wrote {path}: a simulated suit (6 sensors over 4 protocols, insoles); "
          f"imucap devices simulate --setup {path} serves its devices")
    return 0


def _target_problem(path: Path, force: bool) -> str | None:
    folder = path.parent if str(path.parent) else Path(".")
    if path.exists() and not force:
        return f"{path} exists; choose another name, or --force to replace it"
    if not folder.is_dir():
        return f"{folder}: no such folder"
    return None


def _assign_with_devices(sites: list[str], urls: list[str], answers: Answers, seconds: float) -> dict[str, str] | None:
    from app.capture.identify import DeviceReaders, MotionWatcher

    print(f"sites: {', '.join(sites)}" + (" (the classic six; --sites to choose)" if sites == list(CLASSIC_SITES)
                                           else ""))
    print(f"opening {len(urls)} device(s) ...", flush=True)
    watcher = MotionWatcher(urls, clock=time.monotonic)
    with DeviceReaders(urls, watcher) as readers:
        readers.wait_opened(timeout=15.0)
        for url, why in readers.failed.items():
            print(f"  cannot open {url}: {why} (left out)", flush=True)
        opened = [u for u in urls if u in readers.opened]
        if not opened:
            print("imucap setup new: none of the devices could be opened; check power, cables and URLs",
                  file=sys.stderr)
            return None
        print(f"{len(opened)} device(s) open; keep the others still while you move one", flush=True)
        return assign_sites(sites, opened, watcher, answers, seconds)


# ------------------------------------------------------------------------------------- check
def cmd_check(args: argparse.Namespace) -> int:
    from app.capture.check import check_setup
    from app.capture.setup_file import load_setup

    try:
        setup = load_setup(args.file)
    except SetupError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    if not args.json:
        print(f"{args.file}: subject {setup.subject.id} ({setup.subject.height_m:g} m); "
              f"reading {len(setup.urls())} device(s) for {args.seconds:g} s ...", flush=True)
    report = check_setup(setup, args.seconds)
    if args.json:
        print(json.dumps(report.as_json()))
    else:
        print_report(report)
    return 0 if report.ok else 1


def print_report(report) -> None:
    width = max(len(d.name) for d in report.devices)
    for d in report.devices:
        battery = "n/a" if d.battery_pct is None else f"{d.battery_pct:.0f}%"
        serial = ""
        if d.serial_expected is not None:
            serial = ("  serial not reported by this protocol" if d.serial_reported is None
                      else f"  serial {d.serial_reported}")
        print(f"{d.name:<{width}}  {d.url}\n{'':<{width}}  {d.samples} samples, {d.rate_hz:g} Hz, {d.errors} errors, "
              f"{d.lost_packets} lost, battery {battery}{serial}: {'ok' if d.ok else 'PROBLEM'}")
        for p in d.problems:
            print(f"{'':<{width}}  -> {p}")
    for p in report.problems:
        print(f"problem: {p}")
    for w in report.warnings:
        print(f"warning: {w}")
    bad = sum(not d.ok for d in report.devices)
    if report.ok:
        print(f"all {len(report.devices)} device(s) fine")
    else:
        print(f"{bad} of {len(report.devices)} device(s) with a problem" +
              (f", {len(report.problems)} setup problem(s)" if report.problems else ""))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("setup", help="write a setup file by moving each sensor (new); check one (check); "
                                            "the simulated suit's (example)")
    sub = p.add_subparsers(dest="setup_command", required=True)

    pn = sub.add_parser("new", help="interactive: subject, then move each site's sensor when asked")
    pn.add_argument("file", help="the setup file to write (TOML)")
    pn.add_argument("--url", action="append", default=[], help="a candidate device (repeatable; default: every "
                                                               "device `imucap devices list` finds)")
    pn.add_argument("--sites", help=f"sites to ask for, comma separated (default: {','.join(CLASSIC_SITES)})")
    pn.add_argument("--seconds-per-site", type=float, default=20.0, help="a site is skipped after this long")
    pn.add_argument("--force", action="store_true", help="replace FILE when it exists")
    pn.set_defaults(func=cmd_new)

    pc = sub.add_parser("check", help="open every device of a setup file for a few seconds and report")
    pc.add_argument("file", help="the setup file (TOML)")
    pc.add_argument("--seconds", type=float, default=3.0, help="read each device this long")
    pc.add_argument("--json", action="store_true", help="one JSON object")
    pc.set_defaults(func=cmd_check)

    pe = sub.add_parser("example", help="write the simulated suit's setup (every device can be simulated: no "
                                        "hardware needed)")
    pe.add_argument("file", help="the setup file to write (TOML)")
    pe.add_argument("--force", action="store_true", help="replace FILE when it exists")
    pe.set_defaults(func=cmd_example)
