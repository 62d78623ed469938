"""Work the window hands to threads: opening devices, loading models, replays, exports.

Why plain threads polled by a QTimer rather than QThread signals: the work is ordinary
Python (the capture session, ``replay_recording``) that knows nothing of Qt, and a poll
every 50 ms delivers each result on the GUI thread with no cross-thread signal to get
wrong. A job that fails hands its exception back; the window shows it.
"""

from __future__ import annotations

import threading
import traceback
from collections.abc import Callable
from typing import Any

from PySide6 import QtCore


class Cancelled(Exception):
    """Raised inside a job (from its progress callback) when the user cancelled it."""


class Job:
    """One call on its own daemon thread; ``progress`` is whatever the job last reported."""

    def __init__(self, name: str, fn: Callable[..., Any], args: tuple[Any, ...],
                 on_done: Callable[[Any], None] | None, on_error: Callable[[BaseException], None] | None) -> None:
        self.name = name
        self.on_done, self.on_error = on_done, on_error
        self.result: Any = None
        self.error: BaseException | None = None
        self.progress: Any = None
        self.cancelled = threading.Event()
        self.finished = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(fn, args), name=f"gui-job-{name}", daemon=True)

    def _run(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        try:
            self.result = fn(*args)
        except BaseException as exc:  # noqa: BLE001 - handed to the window, which shows it
            self.error = exc
            if not isinstance(exc, Cancelled):
                traceback.print_exc()
        finally:
            self.finished.set()

    def report(self, value: Any) -> None:
        """For the job itself: note progress; raises Cancelled once the user cancelled."""
        self.progress = value
        if self.cancelled.is_set():
            raise Cancelled(self.name)

    def cancel(self) -> None:
        self.cancelled.set()

    def join(self, timeout: float | None = None) -> bool:
        return self.finished.wait(timeout)


class Jobs(QtCore.QObject):
    """Starts jobs and calls their callbacks on the GUI thread when they end."""

    def __init__(self, parent: QtCore.QObject | None = None, interval_ms: int = 50) -> None:
        super().__init__(parent)
        self.pending: list[Job] = []
        self._timer = QtCore.QTimer(self)
        self._timer.timeout.connect(self._poll)
        self._timer.start(interval_ms)

    def run(self, name: str, fn: Callable[..., Any], *args: Any, on_done: Callable[[Any], None] | None = None,
            on_error: Callable[[BaseException], None] | None = None, with_job: bool = False) -> Job:
        """Run ``fn(*args)`` (``fn(job, *args)`` when ``with_job``: it reports progress and
        sees cancellation) on a thread of its own."""
        job = Job(name, fn, args, on_done, on_error)
        if with_job:
            job._thread = threading.Thread(target=job._run, args=(fn, (job, *args)), name=f"gui-job-{name}",
                                           daemon=True)
        self.pending.append(job)
        job._thread.start()
        return job

    def busy(self, name: str) -> bool:
        return any(j.name == name and not j.finished.is_set() for j in self.pending)

    def _poll(self) -> None:
        done = [j for j in self.pending if j.finished.is_set()]
        if not done:
            return
        self.pending = [j for j in self.pending if not j.finished.is_set()]
        for j in done:
            if j.error is None:
                if j.on_done is not None:
                    j.on_done(j.result)
            elif j.on_error is not None:
                j.on_error(j.error)

    def wait_all(self, timeout: float = 10.0) -> None:
        """At exit: give running jobs (a session stopping) a chance to finish."""
        for j in list(self.pending):
            j.join(timeout)
