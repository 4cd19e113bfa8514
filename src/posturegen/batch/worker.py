"""What a worker process runs: chunks of Jobs, one problem at a time.

Solver structures are cached per process (:meth:`posturegen.solver.problem.Problem.compile`, robots
by
``load_bundled``): a worker that lives across many chunks builds each structure once. Any
exception of one problem becomes its :class:`BatchError`; the chunk goes on.
"""

from __future__ import annotations

import ctypes
import os
import pickle
import socket
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError, PosturegenError, PosturegenWarning
from ..io.problem_file import problem_from_dict
from ..solver import compile as compile_module
from ..solver.diagnose import diagnose as diagnose_result
from ..solver.solve import Result, solve
from .jobs import ERROR, INPUT_ERROR, BatchError, BatchItem, Job, read_file


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def _problem(job: Job) -> Any:
    """The Job's Problem, built in this process."""
    if isinstance(job.problem, bytes):
        return pickle.loads(job.problem)
    base = Path(job.base_dir) if job.base_dir is not None else None
    return problem_from_dict(job.problem, base_dir=base)


def _answer(job: Job, diagnose: bool) -> Result | BatchError:
    """Solve one Job (and diagnose a failure when asked); an exception is its BatchError."""
    job = read_file(job)
    if job.error:
        return BatchError(job.name, INPUT_ERROR, job.error)
    try:
        problem = _problem(job)
        result = solve(problem)
        return diagnose_result(problem, result) if diagnose else result
    except InputError as exc:
        return BatchError(job.name, INPUT_ERROR, str(exc))
    except PosturegenError as exc:
        return BatchError(job.name, ERROR, str(exc))
    except Exception as exc:  # one problem's bug must not stop the batch
        text = " ".join(str(exc).split())
        return BatchError(job.name, ERROR, f"{type(exc).__name__}: {text}")


def solve_job(job: Job, diagnose: bool = False) -> BatchItem:
    """One Job's BatchItem: its Result or BatchError, the whole call's time, the warnings."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PosturegenWarning)
        answer = _answer(job, diagnose)
    call, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    raised = tuple((w.category, str(w.message)) for w in caught)
    return BatchItem(job.index, job.name, answer, call, worker_name(), raised, cpu)


def run_chunk(jobs: Sequence[Job], diagnose: bool = False) -> list[BatchItem]:
    """The BatchItems of a chunk of Jobs, in its order."""
    return [solve_job(job, diagnose) for job in jobs]


def warm(jobs: Sequence[Job]) -> None:
    """Solve ``jobs`` and forget the answers: their structures are built in this process."""
    run_chunk(jobs)


@dataclass(frozen=True)
class WorkerInfo:
    """A worker's state: its name, the solver structures it holds, its BLAS threads per
    OpenBLAS library loaded (numpy's, CasADi's IPOPT's)."""

    worker: str
    structures: int
    blas_threads: tuple[tuple[str, int], ...]


def worker_info() -> WorkerInfo:
    """This process's WorkerInfo."""
    return WorkerInfo(worker_name(), len(compile_module._CACHE), blas_threads())


_GET_THREADS = ("openblas_get_num_threads", "scipy_openblas_get_num_threads64_")


def blas_threads() -> tuple[tuple[str, int], ...]:
    """The thread count of every OpenBLAS loaded in this process (Linux: read from
    /proc/self/maps; empty elsewhere)."""
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return ()
    paths = sorted({line.split()[-1] for line in maps if "openblas" in line.split()[-1]})
    out = []
    for path in paths:
        lib = ctypes.CDLL(path)  # the library already loaded: the same handle
        for symbol in _GET_THREADS:
            get = getattr(lib, symbol, None)
            if get is not None:
                out.append((Path(path).name, int(get())))
                break
    return tuple(out)
