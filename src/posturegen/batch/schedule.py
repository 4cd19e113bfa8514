"""Chunks of Jobs on a backend's workers, with failures contained.

A backend (:class:`Backend`: the local process pool, Ray) runs a chunk in a worker and answers
with its BatchItems, or with the exception that lost the chunk (its worker died, or the chunk
could not be sent). The jobs of a lost chunk become *suspects*: each is run again alone, with
nothing else in flight, so that one that loses its worker again is the culprit and only its
item fails (``worker crashed``, or ``error`` with the exception); the batch goes on.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Sequence
from typing import Any, Protocol

from .jobs import CRASHED, ERROR, BatchError, BatchItem, Job

CHUNK_MAX = 8  # problems per chunk at most
CHUNKS_PER_SLOT = 4  # at least this many chunks per slot, for balance and a smooth progress bar


class Backend(Protocol):
    """Where chunks run. ``slots``: chunks in flight at most; ``submit`` returns a handle;
    ``wait`` blocks until at least one handle is done and returns the done ones with their
    BatchItems or the exception that lost the chunk; ``crashed(exc)``: the exception says the
    worker died; ``recover`` is called after a loss (a new pool when the old one broke)."""

    slots: int

    def submit(self, jobs: list[Job]) -> Any: ...

    def wait(self, handles: list[Any]) -> list[tuple[Any, list[BatchItem] | BaseException]]: ...

    def crashed(self, exc: BaseException) -> bool: ...

    def recover(self) -> None: ...


def chunk_size(n_jobs: int, slots: int) -> int:
    """Problems per chunk: up to CHUNK_MAX, at least CHUNKS_PER_SLOT chunks per slot."""
    return max(1, min(CHUNK_MAX, n_jobs // max(1, slots * CHUNKS_PER_SLOT)))


def chunks(jobs: Sequence[Job], size: int) -> list[list[Job]]:
    """``jobs`` cut into consecutive chunks of ``size``."""
    return [list(jobs[i : i + size]) for i in range(0, len(jobs), size)]


def _lost(job: Job, exc: BaseException, crashed: bool) -> BatchItem:
    """The item of a job that lost its worker even alone."""
    if crashed:
        error = BatchError(job.name, CRASHED, f"the worker process died ({type(exc).__name__})")
    else:
        text = " ".join(str(exc).split())
        error = BatchError(job.name, ERROR, f"{type(exc).__name__}: {text}")
    return BatchItem(job.index, job.name, error, 0.0, "")


def run_jobs(backend: Backend, jobs: Sequence[Job], size: int | None = None) -> Iterator[BatchItem]:
    """Every job's BatchItem, in the order they finish (each exactly once)."""
    queue = deque(chunks(jobs, size or chunk_size(len(jobs), backend.slots)))
    suspects: deque[Job] = deque()
    in_flight: dict[Any, tuple[list[Job], bool]] = {}  # handle: (jobs, run alone)
    while queue or suspects or in_flight:
        if suspects:  # alone: wait for the others to finish first
            if not in_flight:
                job = suspects.popleft()
                in_flight[backend.submit([job])] = ([job], True)
        else:
            while queue and len(in_flight) < backend.slots:
                chunk = queue.popleft()
                in_flight[backend.submit(chunk)] = (chunk, False)
        lost = False
        for handle, answer in backend.wait(list(in_flight)):
            chunk, alone = in_flight.pop(handle)
            if not isinstance(answer, BaseException):
                yield from answer
                continue
            lost = True
            if alone:
                yield _lost(chunk[0], answer, backend.crashed(answer))
            else:
                suspects.extend(chunk)
        if lost:
            backend.recover()
