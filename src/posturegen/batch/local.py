"""The local backend: the standard library's process pool on this machine's cores.

Workers are forked from a forkserver that has imported posturegen: each starts clean (no
thread, lock or compiler of the calling process: see posturegen.solver.codegen and _lifeline) with
``OPENBLAS_NUM_THREADS=1`` set before OpenBLAS loaded (posturegen._threads), without importing
Pinocchio and CasADi again. As with every multiprocessing program that does not fork, a script
that starts a batch must guard its top level with ``if __name__ == "__main__":`` (a worker
imports the script). Each worker lives for the whole batch and keeps its solver structures. A
worker that dies breaks the pool: the pool is replaced and the lost chunks' jobs are run again
alone (posturegen.batch.schedule).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Sequence
from concurrent import futures
from concurrent.futures.process import BrokenProcessPool, ProcessPoolExecutor
from typing import Any

from ..errors import SolveError
from .jobs import BatchItem, Job
from .worker import WorkerInfo, run_chunk, warm, worker_info

READY_TIMEOUT_S = 600.0  # a worker that is not up and warm by then fails ready()
ABORT_JOIN_S = 10.0  # [s] abort() waits this long for each terminated worker

_BARRIER: Any = None  # this worker's barrier of ready() (set by _init)


def _init(warm_jobs: Sequence[Job], barrier: Any, started: Any) -> None:
    """Each worker, once: count itself as started, keep the barrier, solve the warm-up."""
    global _BARRIER
    with started.get_lock():
        started.value += 1
    _BARRIER = barrier
    warm(warm_jobs)


def _meet() -> WorkerInfo:
    """Wait until every worker of the pool is here (so each answers once), then answer."""
    _BARRIER.wait(READY_TIMEOUT_S)
    return worker_info()


def _context() -> Any:
    """The forkserver context, posturegen preloaded (spawn where there is no forkserver)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["posturegen"])
    return context


class LocalBackend:
    """``workers`` processes (default ``os.cpu_count()``), two chunks in flight each;
    ``warm`` jobs are solved by each worker when it starts."""

    def __init__(
        self, workers: int | None = None, diagnose: bool = False, warm: Sequence[Job] = ()
    ) -> None:
        self.workers = workers or os.cpu_count() or 1
        self.slots = 2 * self.workers
        self.diagnose = diagnose
        self._warm = list(warm)
        self._context = _context()
        self._started = self._context.Value("i", 0)  # workers that ran _init, every pool
        self._owner: dict[futures.Future, ProcessPoolExecutor] = {}
        self._pool = self._start()

    def _start(self) -> ProcessPoolExecutor:
        self._broken = False
        self._barrier = self._context.Barrier(self.workers)
        return ProcessPoolExecutor(
            self.workers,
            mp_context=self._context,
            initializer=_init,
            initargs=(self._warm, self._barrier, self._started),
        )

    def submit(self, jobs: list[Job]) -> futures.Future:
        """Run a chunk on the pool."""
        future = self._pool.submit(run_chunk, jobs, self.diagnose)
        self._owner[future] = self._pool
        return future

    def wait(self, handles: list[Any]) -> list[tuple[Any, list[BatchItem] | BaseException]]:
        """The chunks done (at least one): their items, or what lost them."""
        done, _ = futures.wait(handles, return_when=futures.FIRST_COMPLETED)
        out: list[tuple[Any, list[BatchItem] | BaseException]] = []
        for future in done:
            pool = self._owner.pop(future, None)
            exc = future.exception()
            if isinstance(exc, BrokenProcessPool) and pool is self._pool:
                self._broken = True
            out.append((future, exc if exc is not None else future.result()))
        return out

    def crashed(self, exc: BaseException) -> bool:
        """A worker died (the pool broke)."""
        return isinstance(exc, BrokenProcessPool)

    def recover(self) -> None:
        """A new pool when the current one broke (its futures are lost); a SolveError when no
        worker ever started (a script without the ``__main__`` guard: its error is above)."""
        if not self._broken:
            return
        self._pool.shutdown(wait=False, cancel_futures=True)
        if self._started.value == 0:
            raise SolveError(
                "the local workers died before they started (a script that runs a batch "
                "must guard its top level with if __name__ == '__main__':)"
            )
        self._pool = self._start()

    def ready(self) -> list[WorkerInfo]:
        """Block until every worker is up and warm; their WorkerInfo, one each."""
        tasks = [self._pool.submit(_meet) for _ in range(self.workers)]
        return [task.result(READY_TIMEOUT_S) for task in tasks]

    def close(self) -> None:
        """Stop the workers (waiting for them; queued chunks are cancelled)."""
        self._pool.shutdown(wait=True, cancel_futures=True)

    def abort(self) -> None:
        """Stop the workers now, their running chunks abandoned (a planner that reached its
        goal does not wait for the transitions still in flight)."""
        processes = dict(getattr(self._pool, "_processes", None) or {})  # CPython's pool
        self._pool.shutdown(wait=False, cancel_futures=True)
        for process in processes.values():
            process.terminate()
        for process in processes.values():
            process.join(ABORT_JOIN_S)
