"""The simulated suit in a process of its own, as real sensors are.

In one process with the live loop, six device threads writing packets compete with the
model for the interpreter lock: beside a training the demo kept 14-17 poses a second of
20. A child process gives the suit its own interpreter, and it makes the demo what a user
has with hardware: the devices on one side of their wires, imucap on the other.

The parent hands over the synthesized signals (a private temporary file: the child must
replay exactly what the demo scores against), the child starts the suit and answers with
one JSON line: each device's URL and clock start. CAN devices go on a bus the child serves
on 127.0.0.1 (``sim_devices.devices.can_loopback``: python-can's ``virtual`` bus is per
process, and multicast would leave the machine). The child runs until its standard input
closes, which also happens when the parent dies, so no suit outlives its demo; on the way
out it prints each device's packet counts.

    python -m sim_devices.suit_process SIGNALS.pkl ASSIGNMENT_JSON SEED [CAN_HOST:PORT]
"""

from __future__ import annotations

import json
import os
import pickle
import selectors
import subprocess
import sys
import tempfile
import threading
from typing import Any

from inference.signals.site_signals import SiteSignals

START_TIMEOUT_S = 30.0


class SuitProcess:
    """A ``SimulatedSuit`` of ``assignment`` (site -> protocol) replaying ``signals`` in a child
    process. ``start()`` returns once every device is up; ``urls()`` and ``t0s`` are then the
    child's; ``stop()`` ends the child and keeps its last packet counts in ``stats``."""

    def __init__(self, signals: SiteSignals, assignment: dict[str, str], seed: int = 0,
                 can_channel: str = "127.0.0.1:0") -> None:
        self.signals = signals
        self.assignment = dict(assignment)
        self.seed = seed
        self.can_channel = can_channel  # port 0: the child takes a free one
        self.proc: subprocess.Popen[str] | None = None
        self._urls: dict[str, str] = {}
        self.t0s: dict[str, float] = {}
        self.stats: dict[str, dict[str, int]] = {}
        self._stderr: list[str] = []
        self._stderr_thread: threading.Thread | None = None

    def start(self) -> SuitProcess:
        fd, path = tempfile.mkstemp(prefix="imucap-suit-", suffix=".pkl")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump(self.signals, f, protocol=pickle.HIGHEST_PROTOCOL)
            cmd = [sys.executable, "-m", "sim_devices.suit_process", path, json.dumps(self.assignment),
                   str(self.seed), self.can_channel]
            self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                         text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
            self._stderr_thread = threading.Thread(target=self._drain_stderr, name="suit-stderr", daemon=True)
            self._stderr_thread.start()
            line = self._read_line(START_TIMEOUT_S)
        finally:
            os.unlink(path)  # the child has read it once it answers (or it has failed)
        if not line:
            self.stop()  # also waits for the child's last words on stderr
            raise RuntimeError(f"the simulated suit did not start: {self._last_error()}")
        hello = json.loads(line)
        self._urls, self.t0s = hello["urls"], hello["t0"]
        return self

    def _read_line(self, timeout: float) -> str:
        assert self.proc is not None and self.proc.stdout is not None
        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            if not sel.select(timeout):
                return ""
        return self.proc.stdout.readline().strip()

    def _drain_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            self._stderr = (self._stderr + [line.rstrip()])[-20:]

    def _last_error(self) -> str:
        lines = [s for s in self._stderr if s.strip()]
        return lines[-1] if lines else f"exit code {self.proc.poll() if self.proc else None}"

    def urls(self) -> dict[str, str]:
        return dict(self._urls)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()  # the child's signal to stop
            proc.wait(10)  # its last line (the counts) is far smaller than a pipe's buffer
            out = proc.stdout.read() if proc.stdout is not None else ""
        except (subprocess.TimeoutExpired, OSError, ValueError):
            proc.kill()
            proc.wait()
            out = ""
        if self._stderr_thread is not None:
            self._stderr_thread.join(2.0)
        for line in out.splitlines():
            if line.startswith("{"):
                self.stats = json.loads(line).get("stats", self.stats)

    def __enter__(self) -> SuitProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    from sim_devices.suit import SimulatedSuit

    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (3, 4):
        print("usage: python -m sim_devices.suit_process SIGNALS.pkl ASSIGNMENT_JSON SEED [CAN_HOST:PORT]",
              file=sys.stderr)
        return 2
    with open(args[0], "rb") as f:
        signals = pickle.load(f)
    assignment = json.loads(args[1])
    kw: dict[str, Any] = {}
    if len(args) == 4:
        kw.update(can_interface="remote", can_channel=args[3])
    suit = SimulatedSuit(signals, assignment, seed=int(args[2]), **kw).start()
    try:
        t0 = {s: d.sim.started_at for s, d in suit.devices.items()}
        print(json.dumps({"urls": suit.urls(), "t0": t0}), flush=True)
        for _ in sys.stdin:  # until the parent closes it, or dies
            pass
    except KeyboardInterrupt:
        pass
    finally:
        suit.stop()
    print(json.dumps({"stats": {s: dict(d.sim.stats) for s, d in suit.devices.items()}}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
