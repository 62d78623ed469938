"""How long a device reader loop like the hub's selector waits for its turn, beside busy Python threads.

    .venv/bin/python benchmarks/selector_gil.py [--seconds 20] [--busy 2] [--intervals 0.005,0.01,0.02] [--json]

A writer process sends 40-byte packets at 100 Hz to 7 pseudo-terminals; in this process one thread reads
them the way ``drivers.hub.readers.Readers._select`` does (a select over every port, a check and a read per
ready port, a short sleep), while ``--busy`` threads run small numpy operations, as the inference, hub and
GUI threads of a live process do between their native calls. Per switch interval (``sys.setswitchinterval``):
the longest time between two reads that found data and how many such gaps exceeded 200 ms. Every hand-over
of the interpreter lock (each select, read and sleep) waits up to one switch interval for the busy threads,
so the loop's gaps grow with it; the live session's silent-sensor check fires at 0.5 s (``SILENT_AFTER_S``)
and the hub's grid waits 50-100 ms for a sample. Why ``app/live/runner.py`` leaves the interval at Python's
5 ms (docs/window.md).
"""

from __future__ import annotations

import argparse
import json
import os
import pty
import select
import subprocess
import sys
import threading
import time
import tty

import numpy as np

WRITER = """
import os, sys, time
fds = [int(x) for x in sys.argv[1:]]
t = time.monotonic()
while True:
    for fd in fds:
        try:
            os.write(fd, b"x" * 40)
        except BlockingIOError:
            pass
    t += 0.01
    time.sleep(max(0.0, t - time.monotonic()))
"""


def measure(interval: float, busy: int, seconds: float, ports: int = 7) -> dict:
    old = sys.getswitchinterval()
    sys.setswitchinterval(interval)
    masters, slaves = [], []
    for _ in range(ports):
        m, s = pty.openpty()
        tty.setraw(m)
        tty.setraw(s)
        os.set_blocking(s, False)
        masters.append(m)
        slaves.append(s)
    writer = subprocess.Popen([sys.executable, "-c", WRITER, *map(str, slaves)], pass_fds=slaves)
    stop = threading.Event()

    def burn() -> None:
        a = np.random.default_rng(0).random((20, 20))
        while not stop.is_set():
            for _ in range(200):
                a = a @ a * 0.01 + 0.5

    threads = [threading.Thread(target=burn, daemon=True) for _ in range(busy)]
    for th in threads:
        th.start()
    end = time.monotonic() + seconds
    last = time.monotonic()
    worst, over = 0.0, 0
    try:
        while time.monotonic() < end:
            ready, _, _ = select.select(masters, [], [], 0.1)
            for fd in ready:
                select.select([fd], [], [], 0)
                os.read(fd, 65536)
            now = time.monotonic()
            if ready:
                worst = max(worst, now - last)
                over += (now - last) > 0.2
                last = now
            time.sleep(0.005)
    finally:
        stop.set()
        writer.kill()
        writer.wait()
        for th in threads:
            th.join()
        for fd in masters + slaves:
            os.close(fd)
        sys.setswitchinterval(old)
    return {"switch_interval_ms": interval * 1e3, "busy_threads": busy, "worst_gap_ms": round(worst * 1e3, 1),
            "gaps_over_200ms": over, "seconds": seconds}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--busy", type=int, default=2)
    ap.add_argument("--intervals", default="0.005,0.01,0.02", help="switch intervals to compare, s")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    rows = [measure(float(x), args.busy, args.seconds) for x in args.intervals.split(",")]
    if args.json:
        print(json.dumps(rows))
    else:
        for r in rows:
            print(f"switch {r['switch_interval_ms']:g} ms, {r['busy_threads']} busy threads: worst gap "
                  f"{r['worst_gap_ms']} ms, {r['gaps_over_200ms']} gaps over 200 ms in {r['seconds']:g} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
