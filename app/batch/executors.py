"""Where a batch's tasks run: a process pool over this machine's cores, or a Dask cluster.

Both take the same ``Task`` objects and give back each one's result as it finishes, in
whatever order. Nothing here schedules, retries or watches workers by hand: the pool is
the standard library's, and on a cluster Dask's scheduler reruns the task of a lost
worker elsewhere (``task`` makes a rerun redo nothing already written).

The local pool starts its workers with ``spawn`` (a clean interpreter each: no copy of
this process's threads or torch state) and one torch thread each; Ctrl-C reaches only
this process (workers ignore SIGINT), which then stops handing out work.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

from app.batch.task import Task, run_task


def _init_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what Ctrl-C means
    os.environ.setdefault("OMP_NUM_THREADS", "1")


class LocalPool:
    """``workers`` processes on this machine (default: one per core)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = max(1, workers or os.cpu_count() or 1)
        self._pool: ProcessPoolExecutor | None = None
        self._pending: set[Future] = set()

    @property
    def description(self) -> str:
        return f"{self.workers} local worker process(es)"

    def run(self, tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("spawn"),
                                         initializer=_init_worker)
        self._pending = {self._pool.submit(run_task, t) for t in tasks}
        while self._pending:
            done, self._pending = wait(self._pending, return_when=FIRST_COMPLETED)
            for f in done:
                if not f.cancelled():
                    yield f.result()
        self.close()

    def stop(self, abandon: bool = False) -> None:
        """Hand out no more tasks; the running ones finish (``abandon``: end them now; their
        outputs are whole or absent, and the next run redoes them)."""
        for f in list(self._pending):
            f.cancel()
        if abandon and self._pool is not None:
            for p in list(getattr(self._pool, "_processes", {}).values()):
                p.terminate()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskCluster:
    """The tasks on the Dask distributed scheduler at ``address`` (``tcp://HOST:8786``): its
    workers must see the recordings and the output folder at the same paths."""

    def __init__(self, address: str, retries: int = 2) -> None:
        self.address = address
        self.retries = retries
        self._client: Any = None
        self._futures: list[Any] = []

    @property
    def description(self) -> str:
        n = len(self._client.scheduler_info().get("workers", {})) if self._client is not None else "?"
        return f"Dask scheduler {self.address} ({n} worker(s))"

    def connect(self) -> DaskCluster:
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
        self._futures = [self._client.submit(run_task, t, pure=False, retries=self.retries) for t in tasks]
        for f in as_completed(self._futures):
            if f.status == "cancelled":
                continue
            yield f.result()
        self.close()

    def stop(self, abandon: bool = False) -> None:  # noqa: ARG002 - a cluster's running tasks are its to end
        if self._client is not None and self._futures:
            self._client.cancel([f for f in self._futures if f.status == "pending"])

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
