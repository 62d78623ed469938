"""A simulated subject in one process and `imucap capture` in another, as the real-time
capture tests run them (``SOLO_MODULES``, tests/conftest.py), each test's capture ended as
soon as what it asserts on is there.

The capture starts first, with ``--wait``: it loads the model and makes its first call
(``Pipeline.warm_up``) while the simulator synthesizes its session, and opens the devices as
soon as they appear, so the simulated subject's lead-in (N-pose before the protocol) only has
to cover the devices' opening, not the capture's whole start. The capture then runs until ``done()`` says so
(the session played out, enough poses recorded) and is ended with Ctrl-C, as a user ends it.
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

CLI = [sys.executable, "-m", "app.cli.main"]
SIM_READY_S = 180.0  # the simulator's synthesis of the session on a busy machine
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


@dataclass
class Simulator:
    proc: subprocess.Popen
    lines: list[str]  # what it printed up to "simulating ..."

    @property
    def duration(self) -> float:
        """The session's length (s): lead-in, calibration protocol, activity."""
        return float(self.lines[-1].split()[1])

    stderr: str = ""  # the tail of what it wrote there, once stopped
    killed: bool = False  # it outlasted the terminate's 10 s

    def stop(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.killed = True
            self.proc.kill()
            self.proc.wait(10)
        if self.proc.stderr is not None:
            self.stderr = self.proc.stderr.read()[-3000:]

    def why_no_log(self, path: Path) -> str:
        """For a test that needs the simulator's --log-sends file: why it is not there."""
        return (f"no {path.name}: the simulator {'was killed after' if self.killed else 'left'} its terminate "
                f"(exit {self.proc.returncode}); its stderr: {self.stderr}")


def start_simulator(args: list[str]) -> Simulator:
    """`imucap devices simulate ARGS`, returned once its devices are up ("simulating ...")."""
    proc = subprocess.Popen([*CLI, "devices", "simulate", *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV)
    lines: queue.Queue[str | None] = queue.Queue()

    def read_stdout() -> None:
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read_stdout, daemon=True).start()
    seen: list[str] = []
    deadline = time.monotonic() + SIM_READY_S
    try:
        while not (seen and seen[-1].startswith("simulating")):
            line = lines.get(timeout=max(0.1, deadline - time.monotonic()))  # queue.Empty past the deadline
            if line is None:
                raise AssertionError("".join(seen) + proc.stderr.read()[-2000:])
            seen.append(line)
    except BaseException:
        Simulator(proc, seen).stop()
        raise
    return Simulator(proc, seen)


def session_end(truth: Path, sim: Simulator, margin: float = 0.5) -> Callable[[], bool]:
    """done() once the simulated session has played out (but ``margin`` s, so the capture
    ends while every device still streams), on the monotonic clock both processes share."""
    from app.capture.simulate import read_truth

    end = read_truth(truth).t0 + sim.duration - margin
    return lambda: time.monotonic() >= end


def recorded(rec: Path, poses: int, calibrated: bool = True) -> Callable[[], bool]:
    """done() once the recording being written holds ``poses`` poses (and a calibration)."""
    from app.recording import read_recording

    def done() -> bool:
        try:
            r = read_recording(rec) if rec.exists() else None
        except Exception:  # noqa: BLE001 - a file being written may not read yet; ask again
            return False
        return r is not None and (r.calibrations or not calibrated) and r.recon["t"].size >= poses

    return done


def run_capture(capture_args: list[str], sim_args: list[str], done: Callable[[Simulator], Callable[[], bool]] | None,
                stdin_text: str = "", ceiling: float = 240.0, poll: float = 0.5,
                window: bool = False) -> tuple[subprocess.CompletedProcess, Simulator]:
    """`imucap capture --wait 120 CAPTURE_ARGS` started, then the simulator (``sim_args``);
    once ``done(sim)()`` holds the capture gets Ctrl-C (with a window, ``done`` is None: it
    quits by its own ``--quit-after``). ``ceiling`` bounds the whole run."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        cmd = [*CLI, "capture", "--wait", "120", *capture_args]
        cap = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=out, stderr=err, text=True, env=ENV)
        sim = None
        try:
            cap.stdin.write(stdin_text)  # each line a marker, as typed
            cap.stdin.close()
            sim = start_simulator(sim_args)
            deadline = time.monotonic() + ceiling
            if done is not None:
                until = done(sim)
                while cap.poll() is None and time.monotonic() < deadline and not until():
                    time.sleep(poll)
                if cap.poll() is None:
                    cap.send_signal(signal.SIGINT)
            cap.wait(max(60.0, deadline - time.monotonic()))
        finally:
            if cap.poll() is None:
                cap.kill()
                cap.wait(10)
            if sim is not None:
                sim.stop()
        out.seek(0)
        err.seek(0)
        return subprocess.CompletedProcess(cmd, cap.returncode, out.read(), err.read()), sim


# what is not real time (a replay, an evaluate, an export) runs niced, so a capture that shares
# the cores with one (test_capture_e2e.py's second) keeps its turn
OFFLINE_NICE = 10


def cli(args: list[str]) -> subprocess.Popen:
    """`imucap ARGS` started, niced, for ``finish``: once the real-time part of a test is over,
    its replay and evaluate run side by side (each on one core)."""
    return subprocess.Popen(["nice", "-n", str(OFFLINE_NICE), *CLI, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def finish(proc: subprocess.Popen, timeout: float = 300) -> subprocess.CompletedProcess:
    out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


_EVALUATIONS: dict[tuple[str, ...], subprocess.Popen | subprocess.CompletedProcess] = {}


def start_evaluate(args: list[str]) -> None:
    """`imucap evaluate ARGS` started, once per test session for the same arguments (its answer
    is a function of its files and arguments): the wired reference that the wireless and the
    three-protocol captures are both held against, on the same motion file."""
    key = tuple(args)
    if key not in _EVALUATIONS:
        _EVALUATIONS[key] = cli(["evaluate", *args])


def evaluated(args: list[str]) -> subprocess.CompletedProcess:
    """What ``start_evaluate(args)`` gave."""
    start_evaluate(args)
    done = _EVALUATIONS[tuple(args)]
    if isinstance(done, subprocess.Popen):
        done = _EVALUATIONS[tuple(args)] = finish(done)
    return done



def sent_times(sends: Path, skip: tuple[str, ...] = ()):
    """Every packet's send time (monotonic clock, sorted) over the simulator's devices (``--log-sends``),
    but those in ``skip``."""
    import numpy as np

    log = np.load(sends)
    return np.sort(np.concatenate([log[k] for k in log.files
                                   if k.endswith("/t") and k.split("/")[0] not in skip] or [np.zeros(0)]))


def sender_stalls(sends: Path, skip: tuple[str, ...] = (), min_s: float = 0.05) -> list[tuple[float, float]]:
    """(start, end) on the monotonic clock of each span of at least ``min_s`` in which no device of the
    simulator sent anything (``--log-sends``; ``skip``: devices it unplugs on purpose). A capture cannot
    receive what was not sent: the presence a test asks of a capture is asked outside these spans."""

    return stall_spans(sent_times(sends, skip), min_s)


def device_stalls(sends: Path, device: str, min_s: float = 0.2) -> list[tuple[float, float]]:
    """(start, end) of each span of at least ``min_s`` in which the simulator's ``device`` sent nothing
    (``--log-sends``). A pseudo-terminal's writer blocks while the kernel's terminal work waits for a core
    (drivers/hub/readers.py): on a loaded machine the simulated Xbus sent nothing for 4.6 s while the
    other devices went on. A capture cannot receive it: a site's presence is asked outside these spans."""
    import numpy as np

    log = np.load(sends)
    return stall_spans(log[f"{device}/t"], min_s) if f"{device}/t" in log.files else []


def stall_spans(sent, min_s: float = 0.05) -> list[tuple[float, float]]:
    """(start, end) of each gap of at least ``min_s`` between consecutive send times."""
    import numpy as np

    gaps = np.diff(sent)
    return [(float(a), float(a + g)) for a, g in zip(sent[:-1][gaps >= min_s], gaps[gaps >= min_s])]


def outside(t, spans: list[tuple[float, float]], margin: float = 0.05):
    """A mask of the times ``t`` not within ``margin`` s after the start of a span or during it."""
    import numpy as np

    keep = np.ones(len(t), dtype=bool)
    for a, b in spans:
        keep &= ~((t > a) & (t < b + margin))
    return keep


def silences(rec: Path, sends: Path, min_s: float = 0.5, skip: tuple[str, ...] = ()) -> str:
    """Which process stopped, when a capture lost every device at once: the spans of at least ``min_s``
    where no site of the recording was present, each with the packets the simulator sent meanwhile
    (``--log-sends``; both on the machine's monotonic clock). Sends there mean the capture stalled; none,
    the simulator did. ``skip``: devices the simulator unplugs on purpose. For a failing test's message."""
    import numpy as np

    from app.recording import read_recording

    try:
        r = read_recording(rec)
        sent = sent_times(sends, skip)
    except Exception as exc:  # noqa: BLE001 - a diagnosis must not hide the failure it explains
        return f"(no silence diagnosis: {exc})"
    t = np.asarray(r.raw["t"], dtype=np.float64)
    anyone = np.zeros(len(t), dtype=bool)
    for s in r.sites:
        anyone |= np.asarray(r.raw[s]["present"], dtype=bool)
    stalls = stall_spans(sent)
    spans, start = [], None
    for i in range(len(t) + 1):
        silent = i < len(t) and not anyone[i]
        if silent and start is None:
            start = i
        elif not silent and start is not None:
            a, b = t[start], t[min(i, len(t) - 1)]
            if b - a >= min_s:
                n = int(np.count_nonzero((sent > a + 0.1) & (sent < b - 0.1)))
                who = "the capture stalled" if n else "the simulator stalled"
                spans.append(f"{a - t[0]:.1f}-{b - t[0]:.1f} s: {n} packets sent ({who})")
            start = None
    # no hub frame at all for a while: the capture's hub made none (a recorded frame is made even when
    # every device is silent), so sends there mean the capture process stalled
    for i in np.flatnonzero(np.diff(t) >= min_s):
        a, b = t[i], t[i + 1]
        n = int(np.count_nonzero((sent > a + 0.1) & (sent < b - 0.1)))
        spans.append(f"{a - t[0]:.1f}-{b - t[0]:.1f} s: no hub frame, {n} packets sent "
                     f"({'the capture stalled' if n else 'both stalled'})")
    return ("silences: " + ("; ".join(spans) if spans else "none") + "; the simulator's own stalls: "
            + (", ".join(f"{a - t[0]:.1f} s ({1000 * (b - a):.0f} ms)" for a, b in stalls) or "none"))
