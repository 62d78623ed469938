"""Watch live pipelines' stall traces and write what the kernel says each of their threads is doing.

A capture under test sometimes gives no hub frame for seconds while its simulator keeps sending
(NOTES.md, "Tests"). faulthandler's dump (``IMUCAP_STALL_TRACE``, app/live/runner.py) shows each
thread's Python frame then, and in the dumps caught so far every thread was waiting: nothing in
the process says which thread holds the interpreter or what the kernel has it waiting for. This
watcher runs outside the captures: when a trace ``<PREFIX>.<pid>`` gets a new dump it reads, for
that pid, each thread's state, kernel wait channel, syscall, time on a core and time waiting for
one (``/proc/<pid>/task/<tid>/{stat,wchan,syscall,schedstat,stack}``), twice 0.5 s apart, with the
machine's pressure stall figures and CPU steal, into ``<PREFIX>.<pid>.proc``.

    python scripts/stall_watch.py PREFIX [PREFIX ...]      # until killed (scripts/test.sh starts it)
"""

from __future__ import annotations

import glob
import os
import re
import sys
import time
from pathlib import Path

POLL_S = 0.1
SECOND_LOOK_S = 0.5


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read()
    except OSError as exc:
        return f"({exc.strerror})"


def _tasks(pid: int) -> dict[int, dict[str, str | int]]:
    out: dict[int, dict[str, str | int]] = {}
    for task in glob.glob(f"/proc/{pid}/task/*"):
        tid = int(task.rsplit("/", 1)[1])
        stat = _read(f"{task}/stat")
        m = re.match(r"\d+ \((.*)\) (\S) (.*)", stat)
        if m is None:
            continue
        rest = m.group(3).split()
        sched = _read(f"{task}/schedstat").split()
        out[tid] = {
            "state": m.group(2),
            "cpu_ticks": int(rest[10]) + int(rest[11]),  # utime + stime (fields 14, 15)
            "on_cpu_ns": int(sched[0]) if len(sched) == 3 else -1,
            "runq_ns": int(sched[1]) if len(sched) == 3 else -1,
            "wchan": _read(f"{task}/wchan").strip() or "-",
            "syscall": _read(f"{task}/syscall").split(" ", 1)[0].strip(),
            "stack": " < ".join(line.split("] ", 1)[-1] for line in _read(f"{task}/stack").splitlines()[:6]),
        }
    return out


def _steal() -> tuple[int, int]:
    """(steal, total) jiffies of the machine's cpu line."""
    fields = [int(x) for x in _read("/proc/stat").splitlines()[0].split()[1:]]
    return (fields[7] if len(fields) > 7 else 0), sum(fields)


def _pressure() -> str:
    return " | ".join(f"{k}: " + _read(f"/proc/pressure/{k}").replace("\n", "; ") for k in ("cpu", "io", "memory"))


def snapshot(pid: int, out: Path, names: dict[int, str]) -> None:
    first, steal0, t0 = _tasks(pid), _steal(), time.monotonic()
    time.sleep(SECOND_LOOK_S)
    second, steal1, dt = _tasks(pid), _steal(), time.monotonic() - t0
    steal = (steal1[0] - steal0[0]) / max(1, steal1[1] - steal0[1])
    lines = [f"=== stall of pid {pid} seen at {t0:.3f} (monotonic); second look {dt:.2f} s later; "
             f"CPU steal over it {steal:.1%}", _pressure(),
             "tid name: state then/now, on a core / waiting for one over the look (ms), wchan, syscall, kernel stack"]
    for tid, a in sorted(first.items()):
        b = second.get(tid, a)
        on = (int(b["on_cpu_ns"]) - int(a["on_cpu_ns"])) / 1e6
        wait = (int(b["runq_ns"]) - int(a["runq_ns"])) / 1e6
        lines.append(f"{tid} {names.get(tid, '?')}: {a['state']}/{b['state']}, {on:.0f} / {wait:.0f} ms, "
                     f"{a['wchan']}, {a['syscall']}, {a['stack'] or '-'}")
    with open(out, "a") as f:
        f.write("\n".join(lines) + "\n")


def watch(prefixes: list[str]) -> None:
    seen: dict[str, int] = {}
    names: dict[str, dict[int, str]] = {}
    while True:
        for prefix in prefixes:
            for path in glob.glob(f"{glob.escape(prefix)}.*"):
                suffix = path[len(prefix) + 1:]
                if not suffix.isdigit():
                    continue
                try:
                    size = os.path.getsize(path)
                except OSError:
                    continue
                if size <= seen.get(path, 0):
                    continue
                with open(path, errors="replace") as f:
                    f.seek(seen.get(path, 0))
                    new = f.read()
                seen[path] = size
                known = names.setdefault(path, {})
                for m in re.finditer(r"^thread 0x[0-9a-f]+ tid (\d+) (.*)$", new, re.M):
                    known[int(m.group(1))] = m.group(2)
                if "Timeout (" in new and os.path.exists(f"/proc/{suffix}"):
                    snapshot(int(suffix), Path(f"{path}.proc"), known)
        time.sleep(POLL_S)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: stall_watch.py PREFIX [PREFIX ...]")
    watch(sys.argv[1:])
