"""The pass of problems never seen (``posturegen bench --cold``): what a user's or a planner's
next problems cost, with nothing compiled for them beforehand.

Each collision family runs in a fresh process (``spawn``) whose ``POSTUREGEN_CACHE`` is an
empty folder (the robot's fitted proxies ship in the package), on problems drawn with a seed
that no other pass uses (COLD_SEED + the bench's seed). Every call of ``posturegen.solve`` is
timed from the process's first, in the default code-generation mode (what a user meets): the
first call pays the robot's program for the contact structure (its declaration and, with a C
compiler, its compilation), the later ones nothing but their solve. The same problems are
written for a peer solver (:mod:`posturegen.bench.peer`, ``tools/drake_peer.sh``), so that
"x times Drake" is measured on them.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..solver import compile as compile_module
from ..solver.solve import solve
from .families import FAMILIES
from .peer import export_problem, write_problems
from .reach import PLANNER_FAMILIES

# the never-seen pass draws its problems with this seed plus the bench's: no other pass of
# `posturegen bench` uses it, so nothing it meets was compiled by them
COLD_SEED = 104_729
COLD_FAMILIES = (
    "talos-reach-balance-collision",
    "talos-stances-collision",
    "talos-near-body-collision",
    "talos-box-collision",
)


def _generator(name: str) -> Callable[[int, int], Any]:
    return {**FAMILIES, **PLANNER_FAMILIES}[name][1]


@dataclass(frozen=True)
class ColdReport:
    """One family's never-seen pass: the first call, then the n - 1 later ones."""

    family: str
    n: int
    seed: int
    first_call_s: float
    first_verified: bool
    verified: int  # of the later calls
    median_call_ms: float
    p90_call_ms: float
    max_call_ms: float
    median_solve_ms: float  # the solvers' own, summed over a call's runs
    median_iterations: float
    later_structures: int  # programs made (declared or loaded) after the first call
    compiled_calls: int  # later calls whose last run used generated C
    failures: tuple[str, ...]

    def line(self) -> str:
        return (
            f"{self.family:<30} cold  n={self.n:<4} first call {self.first_call_s:6.1f} s  "
            f"later: verified {self.verified}/{self.n - 1}  median={self.median_call_ms:6.1f} ms"
            f"  p90={self.p90_call_ms:6.1f}  max={self.max_call_ms:7.1f}  "
            f"iterations median={self.median_iterations:.0f}  structures made "
            f"{self.later_structures}  C {self.compiled_calls}/{self.n - 1}"
        )


def _pass(name: str, n: int, seed: int) -> ColdReport:
    """In the fresh process: solve and time each problem from the first call."""
    calls, solves, iters, failures = [], [], [], []
    verified = compiled = 0
    first_s, first_ok, made_after = 0.0, False, 0
    for i, problem in enumerate(_generator(name)(n, seed)):
        made = sum(compile_module.MADE.values())
        t0 = time.perf_counter()
        result = solve(problem)
        elapsed = time.perf_counter() - t0
        if i == 0:
            first_s, first_ok = elapsed, result.success
            continue
        made_after += sum(compile_module.MADE.values()) - made
        calls.append(1e3 * elapsed)
        solves.append(1e3 * result.solve_time_s)
        iters.append(result.iterations)
        verified += result.success
        compiled += result.generated_c
        if not result.success:
            failures.append(f"#{i}: {result.message}")
    return ColdReport(
        family=name,
        n=n,
        seed=seed,
        first_call_s=first_s,
        first_verified=first_ok,
        verified=verified,
        median_call_ms=statistics.median(calls),
        p90_call_ms=float(np.percentile(calls, 90)),
        max_call_ms=max(calls),
        median_solve_ms=statistics.median(solves),
        median_iterations=statistics.median(iters),
        later_structures=made_after,
        compiled_calls=compiled,
        failures=tuple(failures),
    )


def run_cold(name: str, n: int = 50, seed: int = 0, peer_file: Path | None = None) -> ColdReport:
    """A family's never-seen pass in a fresh process with an empty cache (see the module doc);
    with ``peer_file``, its problems are also written there for the peer solver."""
    draw = COLD_SEED + seed
    root = Path(tempfile.mkdtemp(prefix="posturegen-cold-"))
    try:
        if peer_file is not None:
            items = [export_problem(p, name, i) for i, p in enumerate(_generator(name)(n, draw))]
            write_problems(peer_file, items)
        previous = os.environ.get("POSTUREGEN_CACHE")
        os.environ["POSTUREGEN_CACHE"] = str(root)  # the child's environment
        try:
            with multiprocessing.get_context("spawn").Pool(1) as pool:
                return pool.apply(_pass, (name, n, draw))
        finally:
            if previous is None:
                os.environ.pop("POSTUREGEN_CACHE", None)
            else:
                os.environ["POSTUREGEN_CACHE"] = previous
    finally:
        shutil.rmtree(root, ignore_errors=True)


@dataclass(frozen=True)
class PeerReport:
    """A peer solver's calls on one family's never-seen problems."""

    family: str
    solver: str
    n: int
    successes: int
    verified: int
    median_solve_ms: float  # every call's, failures included (a planner pays them too)
    median_total_ms: float  # the same with building the peer's program

    def line(self) -> str:
        return (
            f"{self.family:<30} peer  {self.solver:<6} n={self.n:<4} success {self.successes}"
            f"  verified {self.verified}  solve median={self.median_solve_ms:7.1f} ms  "
            f"with its build {self.median_total_ms:7.1f} ms"
        )


def run_peer(command: str, problems: Path, results: Path) -> list[PeerReport]:
    """Run the peer (``command PROBLEMS --out RESULTS``, e.g. ``tools/drake_peer.sh``) on the
    written problems and summarize its results per family and solver."""
    subprocess.run([command, str(problems), "--out", str(results)], check=True)
    rows = [json.loads(line) for line in results.read_text().splitlines() if line.strip()]
    out = []
    for key in sorted({(r["family"], r["solver"]) for r in rows}):
        mine = [r for r in rows if (r["family"], r["solver"]) == key]
        out.append(
            PeerReport(
                family=key[0],
                solver=key[1],
                n=len(mine),
                successes=sum(bool(r.get("success")) for r in mine),
                verified=sum(bool(r.get("verified")) for r in mine),
                median_solve_ms=1e3 * statistics.median(r.get("solve_s", np.nan) for r in mine),
                median_total_ms=1e3 * statistics.median(r.get("total_s", np.nan) for r in mine),
            )
        )
    return out


def cold_table(reports: list[ColdReport], peers: list[PeerReport]) -> list[str]:
    """The never-seen pass as a Markdown table, with the peer's best solver beside it."""
    head = (
        "family",
        "n",
        "first call [s]",
        "later calls: verified",
        "median [ms]",
        "p90 [ms]",
        "max [ms]",
        "iterations median",
        "programs made after the first call",
        "Drake's best: solver, verified, median [ms]",
        "speed-up",
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in reports:
        family = r.family.split(" [")[0]  # without the solver's label (--solver a,b)
        mine = [p for p in peers if p.family == family]
        best = min(mine, key=lambda p: p.median_solve_ms) if mine else None
        drake = (
            f"{best.solver}, {best.verified}/{best.n}, {best.median_solve_ms:.0f}" if best else ""
        )
        ratio = f"{best.median_solve_ms / r.median_call_ms:.0f}x" if best else ""
        cells = [
            f"`{r.family}`",
            str(r.n),
            f"{r.first_call_s:.1f}",
            f"{r.verified}/{r.n - 1}",
            f"{r.median_call_ms:.1f}",
            f"{r.p90_call_ms:.1f}",
            f"{r.max_call_ms:.1f}",
            f"{r.median_iterations:.0f}",
            str(r.later_structures),
            drake,
            ratio,
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
