"""Solving a round of sibling transitions: in this process (``workers`` = 1) or on the batch
machinery's local pool (posturegen.batch), which lives for the whole plan so that each worker
builds each solver structure once."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
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


@dataclass
class Timing:
    """Where the postures' time went [s]: ``rounds_s`` the wall time of the rounds (a round
    solved on several workers counts once); the others summed over the postures (across
    workers): the solvers' runs, the builds of their programs, the re-checks, and the rest
    of the calls (active-set rounds' scans, outputs)."""

    rounds_s: float = 0.0
    solver_s: float = 0.0
    build_s: float = 0.0
    verify_s: float = 0.0
    calls_s: float = 0.0

    def add(self, answers: Sequence[Result | BatchError], wall: float) -> None:
        """Count one round's answers, solved in ``wall`` [s]."""
        self.rounds_s += wall
        for r in answers:
            if isinstance(r, Result):
                self.solver_s += r.solve_time_s
                self.build_s += r.build_time_s
                self.verify_s += r.verify_time_s
                self.calls_s += r.wall_time_s

    def to_dict(self) -> dict[str, float]:
        """The times [s], rounded to ms, with ``other_s``: the calls' rest."""
        other = self.calls_s - self.solver_s - self.build_s - self.verify_s
        return {
            "rounds_s": round(self.rounds_s, 3),
            "solver_s": round(self.solver_s, 3),
            "build_s": round(self.build_s, 3),
            "verify_s": round(self.verify_s, 3),
            "other_s": round(max(0.0, other), 3),
        }


class RoundSolver:
    """Solves lists of problem dicts; counts the postures it solved and their time."""

    def __init__(self, workers: int = 1) -> None:
        self.workers = max(1, int(workers))
        self.solved = 0
        self.timing = Timing()
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
        t0 = time.perf_counter()
        self.solved += len(datas)
        if self.workers == 1 or len(datas) == 1 and self._pool is None:
            out = [self._here(p) for p in problems]
        else:
            out = self._pooled(datas)
        self.timing.add(out, time.perf_counter() - t0)
        return out

    def submit(self, data: dict[str, Any]) -> Any:
        """Start solving one problem dict on the pool; its handle for :meth:`wait`."""
        self.solved += 1
        return self._open().submit(make_jobs([data]))

    def wait(self, handles: Sequence[Any]) -> list[tuple[Any, Result | BatchError]]:
        """The problems of ``handles`` that are solved (at least one, blocking until then),
        each with its answer; the wait counts as the postures' time."""
        t0 = time.perf_counter()
        pool = self._open()
        out: list[tuple[Any, Result | BatchError]] = []
        lost = False
        for handle, answer in pool.wait(list(handles)):
            if isinstance(answer, BaseException):
                lost = True
                why = "the worker process died" if pool.crashed(answer) else str(answer)
                out.append((handle, BatchError("posture", "error", why)))
            else:
                out.append((handle, answer[0].result))
        if lost:  # a new pool for the transitions still to come (as batch.schedule does)
            pool.recover()
        self.timing.add([r for _, r in out], time.perf_counter() - t0)
        return out

    def abort(self) -> None:
        """Stop the workers now, abandoning the problems in flight."""
        if isinstance(self._pool, LocalBackend):
            self._pool.abort()
            self._pool = None
        self.close()

    def _open(self) -> LocalBackend | RayBackend:
        if self._pool is None:
            self._pool = open_backend("local", self.workers)
        return self._pool

    def _pooled(self, datas: Sequence[dict[str, Any]]) -> list[Result | BatchError]:
        answers: dict[int, Result | BatchError] = {}
        for item in run_jobs(self._open(), make_jobs(datas), size=1):
            answers[item.index] = item.result
        return [answers[i] for i in range(len(datas))]

    @staticmethod
    def _here(problem: Problem) -> Result | BatchError:
        try:
            return solve(problem)
        except PosturegenError as exc:
            return BatchError(problem.contacts[-1].name, "error", str(exc))
