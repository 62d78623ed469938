"""A ``Pipeline`` run on threads of its own (DESIGN.md: inference never runs on the GUI
thread): an ingest thread polls the frame source (the hub) into a bounded queue (oldest
dropped and counted when inference falls behind, so the output describes *now*), an
inference thread drains it through the Pipeline; the GUI only reads ``latest()``."""

from __future__ import annotations

import faulthandler
import os
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from typing import Any

from app.live.pipeline import LivePose, Pipeline, Sink, run_due
from app.live.sources import FrameSource
from drivers.hub import HubFrame

# a file to which every thread's stack is written when the hub gives no frame for STALL_TRACE_S:
# faulthandler's watchdog is a C thread, so it writes even while a thread holds the interpreter
# (the wireless capture's seconds without a hub frame, NOTES.md "Tests"). Each process writes
# ``<FILE>.<pid>``, with its threads' kernel ids beside their Python idents, so that a watcher
# outside the process (scripts/stall_watch.py) can read what the kernel says each thread is doing
# through a stall: which one holds the interpreter, and whether it waits on the disk or a core
STALL_TRACE_ENV = "IMUCAP_STALL_TRACE"
STALL_TRACE_S = 1.5

# Python's switch interval stays at its default (5 ms). Raised to 20 ms, the window's poses came
# sooner beside busy processes, but the hub's one selector thread, which hands the interpreter
# over at every select and read, waited up to 20 ms each time behind the inference and hub
# threads: beside the test suite the serial and UDP sensors of a capture went silent together
# for 0.5-5 s (6-10 % of their samples lost, calibrations failed) while the CAN ones, on threads
# of their own, lost 0.2 %. A reader loop beside two busy Python threads: worst gap 98 ms at
# 5 ms, 826 ms at 20 ms (benchmarks/selector_gil.py; docs/window.md).


def stall_trace_file() -> Any:
    """This process's stall trace (``<IMUCAP_STALL_TRACE>.<pid>``), opened to append, or None."""
    path = os.environ.get(STALL_TRACE_ENV)
    if not path:
        return None
    trace = open(f"{path}.{os.getpid()}", "a")  # noqa: SIM115 - closed by the ingest thread
    print(f"pid {os.getpid()}", file=trace, flush=True)
    return trace


def _name_threads(trace: Any, named: set[tuple[int, int]]) -> set[tuple[int, int]]:
    """Write each thread not named yet as ``thread 0x<ident> tid <kernel id> <name>``: faulthandler's
    dumps name threads by ident, the kernel's ``/proc/<pid>/task/<tid>`` by kernel id."""
    now = {(t.ident, t.native_id): t.name for t in threading.enumerate() if t.ident and t.native_id}
    for ident, tid in now.keys() - named:
        print(f"thread 0x{ident:016x} tid {tid} {now[ident, tid]}", file=trace)
    return set(now)


class LivePipeline:
    """Runs a Pipeline off the caller's thread.

    ingest thread: ``source.poll()`` every ``poll_interval`` into a bounded queue of
    ``queue_size`` frames (oldest dropped, ``stats.dropped``: those reach no sink, so the
    default holds a minute, and a stalled inference thread passes the backlog over, into the
    recording, when it comes back); inference thread: the
    Pipeline. ``latest()`` is what a GUI timer reads; ``stats()`` a snapshot of the
    counters. Exceptions on either thread stop the run and are kept in ``error``.

    The inference thread takes every frame waiting at once (``Pipeline.push_newest``): all
    go through the calibration and the resampler, and only the newest 20 Hz frame they
    complete is posed, the older ones skipped and counted (``poses_skipped``). A pose that
    took longer than a frame period therefore costs the frames it overlapped, never a
    backlog: the loop is at most that one pose behind.

    ``max_lag`` (s): when the inference thread comes back to the queue, frames older than
    the newest by more than this are dropped (counted) instead of worked through. A poser
    slower than real time then shows the newest motion at a lower frame rate rather than
    an ever older one (the resampler restarts across the hole; the poser continues).
    ``max_lag=None`` turns both off: every frame is pushed and posed in turn, however late
    (a list of frames worked through, as the synchronous chain would).
    """

    def __init__(self, pipeline: Pipeline, source: FrameSource, queue_size: int = 3600,
                 poll_interval: float = 1.0 / 120.0, max_lag: float | None = 0.15) -> None:
        self.pipeline = pipeline
        self.source = source
        self.max_lag = max_lag
        self.queue_size = queue_size
        self.poll_interval = poll_interval
        self._q: deque[HubFrame] = deque()
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._latest: LivePose | None = None
        self._threads: list[threading.Thread] = []
        self.error: BaseException | None = None
        # each command with the number of frames queued before it was called: it runs after
        # those frames and before the later ones (``call``)
        self._commands: deque[tuple[Callable[[Pipeline], Any], int]] = deque()  # (fn, frames before it)
        self._queued_total = 0  # frames ever put in the queue (dropped ones included)

    def start(self, warm_up: bool = True) -> LivePipeline:
        """Start the ingest and inference threads. ``warm_up``: make the model's first call
        here (its runtime builds and sizes itself), not on the first pose after calibration;
        a caller that already did (``Pipeline.warm_up``) before opening its devices says False."""
        if warm_up:
            self.pipeline.warm_up()
        self._stop.clear()
        self._threads = [
            threading.Thread(target=self._guard, args=(self._ingest,), name="pipeline-ingest", daemon=True),
            threading.Thread(target=self._guard, args=(self._infer,), name="pipeline-infer", daemon=True),
        ]
        for th in self._threads:
            th.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        with self._cv:
            self._cv.notify_all()
        for th in self._threads:
            th.join(timeout)
        self._threads = []

    def __enter__(self) -> LivePipeline:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return any(th.is_alive() for th in self._threads)

    def latest(self) -> LivePose | None:
        """The newest reconstructed frame (thread-safe: a reference swap)."""
        return self._latest

    def call(self, fn: Callable[[Pipeline], Any]) -> None:
        """Run ``fn(pipeline)`` on the inference thread (changing the active sites,
        recalibrating, adding or closing a sink) without locking the chain: after every frame
        queued before the call and before any queued after it. On a busy machine the queue
        holds a second or more; run ahead of it, a recorder closed at the user's "stop" lost
        the frames of that second, and one added at "record" gained frames from before."""
        with self._cv:
            self._commands.append((fn, self._queued_total))
            self._cv.notify_all()

    def stats(self) -> dict[str, Any]:
        s = self.pipeline.stats.summary()
        s["queued"] = len(self._q)
        return s

    def _guard(self, fn: Callable[[], None]) -> None:
        try:
            fn()
        except BaseException as exc:  # noqa: BLE001 - kept for the caller, the run stops
            self.error = exc
            traceback.print_exc()
            self._stop.set()
            with self._cv:
                self._cv.notify_all()

    def _ingest(self) -> None:
        # a source that knows when its next frame is due (the hub) is polled right then: a
        # fixed timer adds half its period to every frame's latency on average
        due_in = getattr(self.source, "due_in", None)
        trace = stall_trace_file()
        try:
            self._ingest_loop(due_in, trace)
        finally:
            if trace is not None:
                faulthandler.cancel_dump_traceback_later()
                trace.close()

    def _ingest_loop(self, due_in: Callable[[], float] | None, trace: Any) -> None:
        said = armed = 0.0
        named: set[tuple[int, int]] = set()
        longest_poll = longest_gap = 0.0  # over the second before each "hub frames at" line
        last_frames = time.monotonic()
        while not self._stop.is_set():
            began = time.monotonic()
            frames = self.source.poll()
            if frames and trace is not None:
                now = time.monotonic()
                longest_poll = max(longest_poll, now - began)
                longest_gap = max(longest_gap, now - last_frames)
                last_frames = now
                if now - said >= 1.0:  # where the dumps fall in time (the monotonic clock)
                    named = _name_threads(trace, named)
                    print(f"hub frames at {now:.3f}; longest poll {longest_poll * 1e3:.0f} ms, longest between "
                          f"frames {longest_gap * 1e3:.0f} ms, {len(frames)} now, grid {frames[-1].t:.3f}",
                          file=trace, flush=True)
                    said, longest_poll, longest_gap = now, 0.0, 0.0
                if now - armed >= 0.25:  # re-armed while frames come (each arming starts a C thread)
                    faulthandler.dump_traceback_later(STALL_TRACE_S, file=trace)
                    armed = now
            if frames:
                with self._cv:
                    for f in frames:
                        if len(self._q) >= self.queue_size:
                            self._q.popleft()
                            self.pipeline.stats.dropped += 1  # under the lock, as the inference thread's
                        self._q.append(f)
                        self._queued_total += 1
                    self._cv.notify_all()
            wait = self.poll_interval
            if due_in is not None:
                wait = min(wait, max(due_in(), 0.0005))
            self._stop.wait(wait)

    def _infer(self) -> None:
        while not self._stop.is_set():
            with self._cv:
                while not self._q and not self._commands and not self._stop.is_set():
                    self._cv.wait(0.1)
                batch = list(self._q)
                self._q.clear()
                first = self._queued_total - len(batch)  # the number of the batch's first frame
                # each command before the batch's frame it was called ahead of
                calls = [(min(max(before - first, 0), len(batch)), fn) for fn, before in self._commands]
                self._commands.clear()
            self._work(batch, calls)

    def _work(self, batch: list[HubFrame], calls: list[tuple[int, Callable[[Pipeline], Any]]]) -> None:
        p = self.pipeline
        if self.max_lag is None:  # every frame posed, however late
            for k, f in enumerate(batch):
                run_due(calls, k, p)
                if self._stop.is_set():
                    break
                for lp in p.push(f):
                    self._latest = lp
            run_due(calls, len(batch), p)  # those still due (a sink to close) even when stopping
            return
        newest = batch[-1].t if batch else 0.0
        n_late = sum(newest - f.t > self.max_lag for f in batch)  # the oldest ones: the hub's frames are in time order
        with self._cv:  # the ingest thread counts its drops into the same counter
            p.stats.dropped += n_late
        for k in range(n_late):  # not reconstructed, but recorded and calibrated from
            run_due(calls, k, p)
            p.pass_over(batch[k])
        if n_late == len(batch) or self._stop.is_set():
            run_due(calls, len(batch), p)
            return
        # of the 20 Hz frames the rest completes, the newest is posed and the older ones
        # skipped: a late pose makes the next from fresh data, not a queue
        rest = batch[n_late:]
        poses = p.push_newest(rest, calls=[(k - n_late, fn) for k, fn in calls]) if calls else p.push_newest(rest)
        for lp in poses:
            self._latest = lp

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Block until ``predicate()`` or ``timeout`` s (polling; for tests and the CLI)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            if self.error is not None:
                return False
            time.sleep(0.02)
        return predicate()


def close_sink(live: LivePipeline | None, pipeline: Pipeline, sink: Sink, timeout: float = 5.0) -> None:
    """Take ``sink`` off the pipeline and close it on the pipeline's own thread when it runs
    (a recorder must not be closed between two of its writes), else here."""
    done: list[bool] = []

    def detach(p: Pipeline) -> None:
        if sink in p.sinks:
            p.sinks.remove(sink)
        sink.close()
        done.append(True)

    if live is not None and live.running:
        live.call(detach)
        live.wait_for(lambda: bool(done), timeout)
    if not done:
        detach(pipeline)
