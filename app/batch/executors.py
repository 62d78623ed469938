"""Where a batch's tasks run: worker processes on this machine, or a Dask cluster.

Both take the same ``Task`` objects and give back each one's result as it finishes, in
whatever order, and both survive a worker that dies under a task (a native crash in a
file reader, the kernel's OOM killer, a SIGKILL): that task is one failed result with the
reason, the others go on.

The local pool is a few ``multiprocessing`` processes, each fed one task at a time over its
own pipe, one torch thread each. They come from a fork server (``forkserver``): a clean
interpreter started once, with no copy of this process's threads or torch state, that
imports what a task needs (torch, the poser, the exporters: ``_PRELOAD``) once; each worker,
and each one that replaces a dead one, is a fork of it and starts with them imported. With
``spawn`` every worker imported them itself: ~3 s of CPU each, a third of a short study's
CPU on two workers. It is not ``concurrent.futures``' pool on purpose:
when a worker of that pool dies, the pool breaks, every other worker is ended and every
pending future fails with ``BrokenProcessPool``, without saying whose task killed it.
Here the pipe says which task a worker holds, the process's sentinel says it died (and
its exit code how), and a new worker takes its place. Ctrl-C reaches only this process
(workers ignore SIGINT): ``stop`` hands out no more tasks, ``stop(abandon=True)`` ends
the running ones through ``Process.terminate`` (their outputs are whole or absent; their
temporaries are removed).

On a cluster, Dask's own machinery does the same: its nanny restarts a worker that died
and the scheduler reruns the task elsewhere (``task`` makes a rerun redo nothing already
written); a task that took down ``distributed.scheduler.allowed-failures`` workers comes
back as ``KilledWorker``, a task that raised (``retries`` times) as its exception: both
are that recording's failed result here.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections import deque
from collections.abc import Iterator, Sequence
from multiprocessing.connection import Connection, wait
from typing import Any

from app.batch.task import Task, crashed, failed, one_line, run_task

_CTX = mp.get_context("forkserver")
# what run_task imports on its first task; a module missing here is imported by the worker as before
_PRELOAD = ["torch", "app.batch.task", "app.live.model_choice", "app.live.latency", "app.replay",
            "app.export.formats", "app.recording", "app.capture.simulate", "app.report.build"]
_CTX.set_forkserver_preload(_PRELOAD)


def _init_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what Ctrl-C means
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _worker(conn: Connection) -> None:
    """A worker's life: tasks in, results out, until told to stop (None) or the pipe closes."""
    _init_worker()
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(run_task(task))


def how_it_died(exitcode: int | None) -> str:
    if exitcode is None:
        return "no exit code"
    if exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit code {exitcode}"


class _Worker:
    def __init__(self) -> None:
        self.conn, child = _CTX.Pipe()
        self.process = _CTX.Process(target=_worker, args=(child,), name="imucap-batch-worker", daemon=True)
        try:  # born ignoring SIGINT: a Ctrl-C while it starts up must not end it with its first task
            old = signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:  # not the main thread: its handler is not ours to swap
            old = None
        try:
            self.process.start()
        finally:
            if old is not None:
                signal.signal(signal.SIGINT, old)
        child.close()
        self.task: Task | None = None

    def give(self, task: Task) -> bool:
        try:
            self.conn.send(task)
        except OSError:  # it died idle
            return False
        self.task = task
        return True

    def result(self) -> dict[str, Any] | None:
        """Its task's result when one is waiting in the pipe, else None (it died)."""
        try:
            if self.conn.poll():
                return self.conn.recv()
        except (EOFError, OSError):
            pass
        return None

    def end(self, timeout: float = 5.0) -> None:
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.process.join(timeout)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)
        self.conn.close()


class LocalPool:
    """``workers`` processes on this machine (default: one per core)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = max(1, workers or os.cpu_count() or 1)
        self._stopping = False
        self._abandon = False
        self._busy: list[_Worker] = []
        self._run: Iterator[dict[str, Any]] | None = None

    @property
    def description(self) -> str:
        return f"{self.workers} local worker process(es)"

    def run(self, tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        self._run = self._results(tasks)
        return self._run

    def _results(self, tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        todo = deque(tasks)
        self._stopping = self._abandon = False
        idle = [_Worker() for _ in range(min(self.workers, len(todo)))]
        self._busy = busy = []
        try:
            while True:
                while idle and todo and not self._stopping:
                    w = idle.pop()
                    if w.give(todo[0]):
                        todo.popleft()
                        busy.append(w)
                    else:
                        w.end(0.5)
                        idle.append(_Worker())
                if not busy:
                    break
                ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy]))
                for w in [w for w in busy if w.conn in ready or w.process.sentinel in ready]:
                    task, res = w.task, w.result()
                    if res is not None:
                        busy.remove(w)
                        w.task = None
                        idle.append(w)
                        yield res
                        continue
                    w.process.join(5.0)
                    if w.process.is_alive():
                        continue  # the pipe closed but the process lives on: its sentinel will say
                    busy.remove(w)
                    w.conn.close()
                    if not self._abandon:
                        yield crashed(task, how_it_died(w.process.exitcode), w.process.pid)
                    else:
                        crashed(task, "ended", w.process.pid)  # its temporaries go; no result: not run
                    if todo and not self._stopping:
                        idle.append(_Worker())
        finally:
            for w in idle + busy:
                w.end(0.5 if self._abandon else 5.0)
            self._busy = []

    def stop(self, abandon: bool = False) -> None:
        """Hand out no more tasks; the running ones finish (``abandon``: end them now; their
        outputs are whole or absent, and the next run redoes them)."""
        self._stopping = True
        if abandon:
            self._abandon = True
            for w in list(self._busy):
                if w.process.is_alive():
                    w.process.terminate()

    def close(self) -> None:
        """End everything (after ``run`` was left early: its workers too)."""
        if self._busy:
            self.stop(abandon=True)
        if self._run is not None:
            self._run.close()
            self._run = None


class DaskCluster:
    """The tasks on the Dask distributed scheduler at ``address`` (``tcp://HOST:8786``): its
    workers must see the recordings and the output folder at the same paths."""

    def __init__(self, address: str, retries: int = 2) -> None:
        self.address = address
        self.retries = retries
        self._client: Any = None
        self._futures: dict[Any, Task] = {}

    @property
    def description(self) -> str:
        n = len(self._client.scheduler_info().get("workers", {})) if self._client is not None else "?"
        return f"Dask scheduler {self.address} ({n} worker(s))"

    def connect(self) -> DaskCluster:
        from drivers.extras import need

        need("distributed", "imucap batch --cluster")
        from distributed import Client

        try:
            self._client = Client(self.address, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise OSError(f"--cluster {self.address}: no Dask scheduler answers ({exc})") from exc
        return self

    def run(self, tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        from distributed import as_completed

        if self._client is None:
            self.connect()
        self._futures = {self._client.submit(run_task, t, pure=False, retries=self.retries): t for t in tasks}
        for f in as_completed(list(self._futures)):
            if f.status == "cancelled":
                continue
            try:
                yield f.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker (it took workers down with it), or it raised
                task = self._futures[f]
                name = type(exc).__name__
                yield (crashed(task, f"{name}: {one_line(exc)}") if name == "KilledWorker"
                       else failed(task, one_line(exc)))
        self.close()

    def stop(self, abandon: bool = False) -> None:  # noqa: ARG002 - a cluster's running tasks are its to end
        """Hand out no more tasks and give up the running ones (a worker in the middle of one
        finishes it, its outputs whole, and the next run takes them from its journal)."""
        if self._client is not None and self._futures:  # a running task's future is "pending" too
            self._client.cancel([f for f in self._futures if f.status in ("pending", "lost")])

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
