"""Whole calls as a planner meets them (issue 17): ``posturegen.solve(problem)`` timed from
the first call of a fresh process whose disk caches are warm, then in the steady state.

A family (:data:`posturegen.bench.reach.PLANNER_FAMILIES`) runs in two child processes
started afresh (``spawn``): the first solves the 2n problems untimed, so that the fitted
proxies and every compiled library the problems meet are on disk; the second, a fresh
interpreter, times every call: the *first pass* (problems 0..n-1, the first call included:
it loads the robot, its proxies and its solvers), the *steady state* (problems n..2n-1,
after the first pass) and the *nearest* pass (problems 2n..3n-1, each started from the
nearest verified solution of the calls before it: :class:`posturegen.solver.starts.
NearestStarts`, what a planner's loop can do). A call is the whole of ``solve``: parameters,
IPOPT's runs, the active set's rounds and the re-check.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import statistics
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..solver.solve import solve
from ..solver.starts import NearestStarts
from .reach import PLANNER_FAMILIES


@dataclass(frozen=True)
class PassStats:
    """The calls of one pass: verified postures, medians and spread of the times [ms]."""

    n: int
    verified: int
    median_call_ms: float
    p90_call_ms: float
    max_call_ms: float
    median_solve_ms: float  # IPOPT's own wall time, summed over a call's runs
    median_iterations: float
    max_iterations: int
    c_solves: int  # calls whose last IPOPT run used a compiled library
    building_calls: int  # calls that built a structure (symbolic program, solver, library)
    failures: tuple[str, ...]


@dataclass(frozen=True)
class PlannerReport:
    """A planner family's first pass, steady state and nearest-start pass."""

    family: str
    description: str
    jit: bool
    first: PassStats
    steady: PassStats
    nearest: PassStats | None = None

    def line(self) -> str:
        """One line per pass."""
        return "\n".join(
            f"{self.family:<30} {label:<6} n={s.n:<4} verified={100 * s.verified / s.n:5.1f}%  "
            f"call median={s.median_call_ms:6.1f} ms  p90={s.p90_call_ms:6.1f}  "
            f"max={s.max_call_ms:7.1f}  solve median={s.median_solve_ms:6.1f} ms  "
            f"iterations median={s.median_iterations:.0f} max={s.max_iterations}  "
            f"C {s.c_solves}/{s.n}  building calls {s.building_calls}"
            for label, s in (
                ("first", self.first),
                ("steady", self.steady),
                ("nearest", self.nearest),
            )
            if s is not None
        )


def _problems(name: str, n: int, seed: int, jit: bool) -> list[Any]:
    """The family's 3n problems, each with codegen ``sync`` (``jit``) or ``off``."""
    problems = list(PLANNER_FAMILIES[name][1](3 * n, seed))
    mode = "sync" if jit else "off"
    for problem in problems:
        problem.solver_options = dataclasses.replace(problem.solver_options, codegen=mode)
    return problems


def _pass(problems: list[Any], starts: NearestStarts, nearest: bool = False) -> PassStats:
    """Solve and time each problem (the whole call; with ``nearest``, the search for the
    nearest start included), each verified solution added to ``starts``."""
    calls, solves, iters, failures = [], [], [], []
    verified = c_solves = building = 0
    for i, problem in enumerate(problems):
        t0 = time.perf_counter()
        result = solve(problem, start=starts.nearest(problem) if nearest else None)
        calls.append(1e3 * (time.perf_counter() - t0))
        starts.add(problem, result)
        building += result.build_time_s > 0
        c_solves += bool(problem.compile().library)
        solves.append(1e3 * result.solve_time_s)
        iters.append(result.iterations)
        verified += result.success
        if not result.success:
            failures.append(f"#{i}: {result.message}")
    return PassStats(
        n=len(problems),
        verified=verified,
        median_call_ms=statistics.median(calls),
        p90_call_ms=float(np.percentile(calls, 90)),
        max_call_ms=max(calls),
        median_solve_ms=statistics.median(solves),
        median_iterations=statistics.median(iters),
        max_iterations=max(iters),
        c_solves=c_solves,
        building_calls=building,
        failures=tuple(failures),
    )


def _child(name: str, n: int, seed: int, jit: bool) -> PlannerReport:
    """In a child process: the three passes."""
    problems, starts = _problems(name, n, seed, jit), NearestStarts()
    first, steady = _pass(problems[:n], starts), _pass(problems[n : 2 * n], starts)
    nearest = _pass(problems[2 * n :], starts, nearest=True)
    return PlannerReport(name, PLANNER_FAMILIES[name][0], jit, first, steady, nearest)


def _in_fresh_process(name: str, n: int, seed: int, jit: bool) -> PlannerReport:
    """:func:`_child` in a new interpreter (``spawn``: nothing inherited but the arguments)."""
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(_child, (name, n, seed, jit))


def run_planner_family(name: str, n: int = 100, seed: int = 0, jit: bool = False) -> PlannerReport:
    """A planner family's first pass, steady state and nearest pass, each of n problems, in
    a fresh process after another one warmed the disk caches (see the module doc)."""
    _in_fresh_process(name, n, seed, jit)  # the disk caches warmed
    return _in_fresh_process(name, n, seed, jit)
