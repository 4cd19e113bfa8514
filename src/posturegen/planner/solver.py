"""Solving a round of sibling transitions: in this process (``workers`` = 1) or on the batch
machinery's local pool (posturegen.batch), which lives for the whole plan so that each worker
builds each solver structure once."""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType
from typing import Any

from ..batch import BatchError, open_backend
from ..batch.jobs import make_jobs
from ..batch.local import LocalBackend
from ..batch.ray_backend import RayBackend
from ..batch.schedule import run_jobs
from ..errors import PosturegenError
from ..solver.problem import Problem
from ..solver.solve import Result, solve


class RoundSolver:
    """Solves lists of problem dicts; counts the postures it solved."""

    def __init__(self, workers: int = 1) -> None:
        self.workers = max(1, int(workers))
        self.solved = 0
        self._pool: LocalBackend | RayBackend | None = None

    def __enter__(self) -> RoundSolver:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (if any were started)."""
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def solve(
        self, datas: Sequence[dict[str, Any]], problems: Sequence[Problem]
    ) -> list[Result | BatchError]:
        """Each problem's answer, in order (``problems``: the same, already built here)."""
        self.solved += len(datas)
        if self.workers == 1 or len(datas) == 1 and self._pool is None:
            return [self._here(p) for p in problems]
        if self._pool is None:
            self._pool = open_backend("local", self.workers)
        answers: dict[int, Result | BatchError] = {}
        for item in run_jobs(self._pool, make_jobs(datas), size=1):
            answers[item.index] = item.result
        return [answers[i] for i in range(len(datas))]

    @staticmethod
    def _here(problem: Problem) -> Result | BatchError:
        try:
            return solve(problem)
        except PosturegenError as exc:
            return BatchError(problem.contacts[-1].name, "error", str(exc))
