"""A setup's simulated devices in a process of their own: ``imucap devices simulate --setup``.

Why a child process: real sensors are outside imucap, on the far side of their wires. In the
window's process, a dozen device threads writing packets compete with the model and the
drawing for the interpreter lock and skew what the window shows of latency; in a child the
window runs as it does with hardware. The demo window, "Simulate devices", the end-to-end
bench and the window tests all start the simulator this way.

The child runs until its standard input closes (``--while-stdin-open``), which also happens
when this process dies, so no simulator outlives the window that started it. CAN devices
must then share a bus across processes: the child serves theirs on 127.0.0.1 (python-can's
``remote`` interface, ``sim_devices/devices/can_loopback.py``), not the per-process ``virtual`` bus.
"""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from app.capture.setup_file import Setup, save_setup

START_TIMEOUT_S = 120.0  # synthesis of a long activity on a busy machine takes tens of seconds
STOP_TIMEOUT_S = 10.0


class SimulatorProcess:
    """``setup``'s devices, worn by a simulated subject who follows the setup's calibration
    protocol, then ``motion`` (a procedural kind or a motion file) for ``seconds``.

    ``start()`` returns once every device is up (``urls``: name -> URL as the child opened
    them; ``duration``: the whole simulation in seconds); ``stop()`` ends the child; a
    stopped simulator can be started again, from the beginning of the protocol. ``args``:
    more options of ``imucap devices simulate`` (``--truth F``, ``--log-sends F``,
    ``--unplug D:AT:S``)."""

    def __init__(self, setup: Setup | str | os.PathLike, motion: str = "walk", seconds: float = 60.0,
                 seed: int = 0, noise: bool = True, lead_in: float = 4.0, args: Sequence[str] = ()) -> None:
        self.setup = setup
        self.motion = motion
        self.seconds = seconds
        self.seed = seed
        self.noise = noise
        self.lead_in = lead_in
        self.args = list(args)
        self.proc: subprocess.Popen[str] | None = None
        self.urls: dict[str, str] = {}
        self.duration: float | None = None
        self.stats: str | None = None  # the child's last line on stderr: packets per device
        self._stderr: deque[str] = deque(maxlen=40)
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._threads: list[threading.Thread] = []
        self._folder: tempfile.TemporaryDirectory[str] | None = None

    def spec(self) -> dict[str, Any]:
        """What the simulated subject does, as plain data (file arguments by name only:
        their paths are the machine's)."""
        return {"motion": self.motion, "activity_s": self.seconds, "seed": self.seed, "noise": self.noise,
                "lead_in_s": self.lead_in, "options": [a for a in self.args if a.startswith("--")]}

    # ------------------------------------------------------------------ lifecycle
    def command(self, setup_path: str | os.PathLike) -> list[str]:
        return [sys.executable, "-m", "app.cli.main", "devices", "simulate", "--setup", str(setup_path),
                "--motion", self.motion, "--activity-seconds", f"{self.seconds:g}", "--seed", str(self.seed),
                "--lead-in", f"{self.lead_in:g}", "--noise", "typical" if self.noise else "none",
                "--while-stdin-open", *self.args]

    def start(self, timeout: float = START_TIMEOUT_S) -> SimulatorProcess:
        if self.proc is not None:
            raise RuntimeError("the simulator is already running")
        if isinstance(self.setup, Setup):
            self._folder = tempfile.TemporaryDirectory(prefix="imucap-simulator-")
            path: str | os.PathLike = Path(self._folder.name) / "setup.toml"
            save_setup(self.setup, path)
        else:
            path = self.setup
        self._lines, self._stderr = queue.Queue(), deque(maxlen=40)
        self.urls, self.duration, self.stats = {}, None, None
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1"}
        self.proc = subprocess.Popen(self.command(path), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env)
        self._threads = [threading.Thread(target=self._read_stdout, name="simulator-stdout", daemon=True),
                         threading.Thread(target=self._read_stderr, name="simulator-stderr", daemon=True)]
        for th in self._threads:
            th.start()
        try:
            self._wait_ready(timeout)
        except BaseException:
            self.stop()
            raise
        return self

    def _wait_ready(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        while True:
            try:
                line = self._lines.get(timeout=max(0.0, end - time.monotonic()))
            except queue.Empty:
                raise RuntimeError(f"the simulated devices did not start within {timeout:g} s") from None
            if line is None:  # the child closed its output: it failed
                self._join_output()
                raise RuntimeError(f"the simulated devices did not start: {self.last_error()}")
            if line.startswith("simulating"):
                self.duration = float(line.split()[1])
                return
            name, _, url = line.strip().partition(" ")
            if url:
                self.urls[name] = url

    def stop(self) -> None:
        """End the child (its standard input closed: it stops its devices and says what they
        sent), or kill it when it does not end."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()
        except OSError:
            pass
        try:
            proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(STOP_TIMEOUT_S)
        self._join_output()
        if self._stderr:
            self.stats = self._stderr[-1].strip()
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None

    def restart(self) -> SimulatorProcess:
        """From the beginning again (the subject starts over with the calibration protocol)."""
        self.stop()
        return self.start()

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def last_error(self) -> str:
        lines = [ln.strip() for ln in self._stderr if ln.strip()]
        return lines[-1] if lines else f"exit code {self.proc.returncode if self.proc else '?'}"

    def __enter__(self) -> SimulatorProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ the child's output
    def _read_stdout(self) -> None:
        proc = self.proc
        assert proc is not None and proc.stdout is not None
        for line in proc.stdout:
            self._lines.put(line)
        self._lines.put(None)

    def _read_stderr(self) -> None:
        proc = self.proc
        assert proc is not None and proc.stderr is not None
        for line in proc.stderr:
            self._stderr.append(line)

    def _join_output(self) -> None:
        for th in self._threads:
            th.join(STOP_TIMEOUT_S)
        self._threads = []


__all__ = ["SimulatorProcess", "START_TIMEOUT_S"]
