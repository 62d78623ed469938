"""`imucap capture`: capture from the devices a setup file names.

    imucap capture --setup FILE [--record OUT.h5] [--headless] [--seconds N] [--json]
                   [--calibration REC.h5|CAL.json] [--countdown S] [--timeout S]
                   [--stream lsl,vmc,vrchat]

Opens every device, walks the subject through the setup's calibration protocol (each
step printed as it comes, with a countdown and live stillness feedback), then
reconstructs live and records. Headless, one status line (frames/s, latency, each
device's state) that fits a laptop terminal; every line typed on the standard input sets
a marker labelled with it (Enter alone: a numbered marker). Ctrl-C ends cleanly: devices
closed, the recording finalised.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

from app.capture.session import CaptureOptions, CaptureSession, SessionEvent
from app.cli.window_args import add_window_arguments
from app.streams import add_stream_arguments, sinks_from_args


def check_record_target(path: Path) -> str | None:
    """Why ``path`` cannot be recorded to, or None: checked before the capture starts, so a
    read-only or missing folder is refused while nothing is lost yet."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.exists():
        return f"{folder}: the folder does not exist; create it or choose another --record path"
    if not folder.is_dir():
        return f"{folder}: not a folder"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{folder}: not writable; choose another --record path"
    if path.exists() and not os.access(path, os.W_OK):
        return f"{path}: exists and is read-only"
    return None


def load_calibration(path: str):
    """A calibration to reuse: the last one of a recording, or a calibration JSON file."""
    from calibration import Calibration

    p = Path(path)
    if not p.exists():
        raise ValueError(f"--calibration {p}: no such file")
    if p.suffix.lower() in (".h5", ".hdf5"):
        from app.recording import read_recording

        rec = read_recording(p)
        if not rec.calibrations:
            raise ValueError(f"--calibration {p}: the recording holds no calibration")
        return rec.calibrations[-1][1]
    try:
        return Calibration.load(p)
    except (ValueError, KeyError, json.JSONDecodeError) as exc:
        raise ValueError(f"--calibration {p}: not a calibration ({exc})") from None


class _Terminal:
    """The headless display: one status line, rewritten in place on a terminal; events on
    lines of their own above it."""

    def __init__(self, stream=sys.stderr) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.last = ""
        self.last_t = 0.0
        self.lock = threading.Lock()

    def status(self, line: str) -> None:
        with self.lock:
            if self.tty:
                self.stream.write("\r" + line.ljust(len(self.last)))
                self.stream.flush()
            elif line != self.last and time.monotonic() - self.last_t > 2.0:
                self.stream.write(line + "\n")
                self.stream.flush()
                self.last_t = time.monotonic()
            self.last = line

    def event(self, ev: SessionEvent) -> None:
        with self.lock:
            stamp = time.strftime("%H:%M:%S")
            text = f"{stamp} {ev.kind.replace('_', ' ')}: {ev.detail}" if ev.detail else f"{stamp} {ev.kind}"
            self.stream.write(("\r" if self.tty else "") + text.ljust(len(self.last)) + "\n")
            self.stream.flush()


def _markers_from_stdin(session: CaptureSession, stop: threading.Event) -> None:
    count = 0
    for line in sys.stdin:
        if stop.is_set():
            return
        count += 1
        session.add_marker(line.strip() or f"marker {count}")


def run(args: argparse.Namespace) -> int:
    from app.capture.setup_file import SetupError, load_setup

    try:
        setup = load_setup(args.setup)
    except (SetupError, OSError) as exc:
        print(f"imucap capture: {exc}", file=sys.stderr)
        return 2
    record = Path(args.record) if args.record else None
    if record is not None:
        why = check_record_target(record)
        if why:
            print(f"imucap capture: cannot record: {why}", file=sys.stderr)
            return 2
    try:
        cal = load_calibration(args.calibration) if args.calibration else None
        if cal is not None:
            missing = [s for s in setup.sites() if s not in cal.sites]
            if missing:
                raise ValueError(f"--calibration {args.calibration}: has no {', '.join(missing)}")
    except ValueError as exc:
        print(f"imucap capture: {exc}", file=sys.stderr)
        return 2
    headless = args.headless or not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    term = _Terminal()
    options = CaptureOptions(record=record, calibration=cal, countdown=args.countdown, timeout=args.timeout,
                             on_event=term.event, latency=args.latency, confidence=args.confidence,
                             reach=not args.no_reach)
    try:
        options.sinks = sinks_from_args(args)
        session = CaptureSession(setup, options)
    except (ValueError, OSError) as exc:
        print(f"imucap capture: {exc}", file=sys.stderr)
        return 2
    # the model's first call (its runtime's build: seconds on a busy machine) while the devices
    # are switched on, not once they stream: a subject already in the N-pose waits less
    session.pipeline.warm_up()
    if args.wait:
        from app.capture.waiting import wait_for_devices

        try:
            wait_for_devices(setup.urls(), args.wait, say=lambda m: print(f"imucap capture: {m}", file=sys.stderr))
        except (OSError, ValueError) as exc:
            print(f"imucap capture: {exc}", file=sys.stderr)
            return 2
    if not headless:
        from app.gui.capture_window import run_capture_window

        return run_capture_window(session, args)
    stop = threading.Event()

    def on_signal(signum, frame):  # noqa: ARG001
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    # past a file-size limit a write fails (the recorder says so and the capture goes on)
    # instead of the signal killing the process with the session
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        try:
            session.start()
        except (ValueError, OSError) as exc:
            print(f"imucap capture: {exc}", file=sys.stderr)
            session.stop()
            return 2
        if sys.stdin is not None and not sys.stdin.closed:
            threading.Thread(target=_markers_from_stdin, args=(session, stop), daemon=True).start()
        end = time.monotonic() + args.seconds if args.seconds else None
        while not stop.is_set() and (end is None or time.monotonic() < end):
            session.poll()
            term.status(session.status_line())
            stop.wait(0.25)
    finally:
        session.stop()
        for s, h in old.items():
            signal.signal(s, h)
    if term.tty:
        sys.stderr.write("\n")
    res = session.result()
    if args.json:
        print(json.dumps(res, default=str))
    else:
        print(f"{res['frames']} poses at {res['fps']} fps; calibration: {res['calibration_status']}")
        if res.get("advice"):
            print(f"imucap capture: {res['advice']}", file=sys.stderr)
        if record is not None:
            print(f"recorded {record}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("capture", help="capture from the devices of a setup file: calibrate, view, record")
    p.add_argument("--setup", required=True, help="setup file (imucap setup new FILE writes one)")
    p.add_argument("--record", help="record the session to this HDF5 file")
    p.add_argument("--headless", action="store_true", help="no window: a status line in the terminal")
    p.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="print one JSON object at the end")
    p.add_argument("--calibration", help="reuse the calibration of an earlier recording (or a calibration JSON)")
    p.add_argument("--wait", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds for devices that are not there yet (switched on, or a simulator "
                        "starting); default: a missing device is an error at once")
    p.add_argument("--countdown", type=float, default=3.0, help="seconds counted down before the first step")
    p.add_argument("--timeout", type=float, default=30.0, help="seconds a calibration step may wait")
    p.add_argument("--latency", default="centred", choices=("centred", "low"),
                   help="low: wait for no future sample (trailing acceleration filter; docs/latency.md)")
    p.add_argument("--confidence", action="store_true",
                   help="each pose with a spread per segment (deg) and for the root (m): 0 where a sensor measured "
                        "it, larger where the model guessed; coloured in the window, in the recording, on LSL "
                        "(docs/confidence.md); costs ~40 %% more per frame")
    p.add_argument("--no-reach", action="store_true",
                   help="with a VR rig: leave the arms as the model gives them instead of reaching the tracked "
                        "controllers (docs/vr_input.md)")
    add_stream_arguments(p)
    add_window_arguments(p)
    p.set_defaults(func=run)
