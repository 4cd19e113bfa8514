"""Batches of problems on every core (``backend="local"``) or on a Ray cluster (``"ray"``).

    >>> results = pg.solve_many(["a.yaml", {...}, problem], workers=2)
    >>> [r.success for r in results]          # input order

A problem is a :class:`~posturegen.solver.problem.Problem`, a problem-file dict or a path; each
answer is the frozen :class:`~posturegen.solver.solve.Result` of ``pg.solve`` (``diagnose=True``: of
``pg.diagnose``), or a :class:`BatchError` (``success`` False) when the problem could not be
built, raised, or lost its worker: one failure never stops the batch. Each worker lives for the
whole batch and builds each solver structure once (posturegen.batch.worker).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from ..solver.solve import Result
from .backends import BACKENDS, open_backend
from .jobs import BatchError, BatchItem, make_jobs
from .schedule import run_jobs

__all__ = ["BACKENDS", "BatchError", "BatchItem", "open_backend", "run_batch", "solve_many"]


def run_batch(
    problems: Iterable[Any],
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    diagnose: bool = False,
    chunk: int | None = None,
) -> Iterator[BatchItem]:
    """Every problem's :class:`BatchItem`, as they finish (``item.index``: its input
    position); the workers stop when the iterator ends or is closed."""
    jobs = make_jobs(problems)
    if not jobs:
        return
    pool = open_backend(backend, workers, address, diagnose)
    try:
        yield from run_jobs(pool, jobs, chunk)
    finally:
        pool.close()


def solve_many(
    problems: Iterable[Any],
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    diagnose: bool = False,
    progress: Callable[[BatchItem], None] | None = None,
) -> list[Result | BatchError]:
    """Solve every problem on ``workers`` processes (default: every core, or the Ray
    cluster's CPUs); the answers in input order. The workers' warnings are raised here, each
    prefixed with its problem's name; ``progress`` is called with each item as it finishes.

    Args:
        problems: problem files (paths), problem dicts or Problems.
        workers: processes (default: every core, or the Ray cluster's CPUs).
        backend: ``local`` or ``ray``; address: the Ray cluster's (default: a local one).
        diagnose: diagnose each failure (one or two more solves each).
        progress: called with each BatchItem as it finishes.

    Returns:
        Per problem, in input order: its Result, or a BatchError (``input error``, ``error``,
        ``worker crashed``) when it gave none."""
    answers: dict[int, Result | BatchError] = {}
    for item in run_batch(problems, workers, backend, address, diagnose):
        answers[item.index] = item.result
        for category, message in item.warnings:
            warnings.warn(f"{item.name}: {message}", category, stacklevel=2)
        if progress is not None:
            progress(item)
    return [answers[i] for i in range(len(answers))]
