"""``posturegen bench --batch``: postures per second of one seeded family in one process, on 1,
2 and ``os.cpu_count()`` local workers, and on a local Ray instance.

Each configuration starts its workers, has each solve the family's warm-up problem (its solver
structure built, like the first solve of ``posturegen bench``) and waits for all of them; then
the n problems are timed. A row gives the warm rate (the n problems only) and the cold one (the
workers' start and warm-up counted too), and how many structures were built during the timed
part (0: every worker reused the one it built while warming up). On a machine shared with
other work the rates say little alone: the workers' CPU share (their CPU time over workers x
wall time; 1 when each had a core to itself) and the CPU per call say whether the workers
waited for cores, and the dispatch CPU what this process spent per posture sending problems
and receiving Results (on 2 cores, time taken from the workers). The rate over the CPU share
estimates the rate the workers would reach with a core each (it ignores the dispatch CPU's
competition for those cores): on a loaded machine, compare those.
"""

from __future__ import annotations

import dataclasses
import os
import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import date
from pathlib import Path

from ..batch.backends import open_backend
from ..batch.jobs import BatchItem, Job, make_jobs
from ..batch.report import percentile
from ..batch.schedule import run_jobs
from ..batch.worker import WorkerInfo, solve_job, worker_info
from ..errors import InputError
from ..solver.solve import Result
from .families import FAMILIES

DEFAULT_FAMILY = "talos-stand-reach"


@dataclass(frozen=True)
class ScalingRow:
    """One configuration's numbers (times in s, rates in postures/s)."""

    backend: str  # in-process | local | ray
    workers: int
    n: int
    verified: int
    start_s: float  # workers up and warm
    wall_s: float  # the n problems on warm workers
    rate: float
    cold_rate: float  # n / (start_s + wall_s)
    median_call_ms: float
    p95_call_ms: float
    median_cpu_ms: float  # the worker's CPU time in a call
    cpu_share: float  # the workers' CPU time over workers x wall time (1: each had a core)
    dispatch_cpu_ms: float  # this process's CPU time per posture, beyond solving
    builds: int  # structures built during the timed part
    blas_threads: int  # the most threads of any OpenBLAS in any worker (0: not seen)
    speedup: float = float("nan")  # rate / the 1-worker local rate

    def cells(self) -> list[str]:
        """The row of the Markdown table."""
        return [
            self.backend,
            str(self.workers),
            f"{self.verified}/{self.n}",
            f"{self.rate:.1f}",
            f"{self.speedup:.2f}x",
            f"{self.rate / self.cpu_share:.1f}",
            f"{self.cold_rate:.1f}",
            f"{self.start_s:.1f}",
            f"{self.median_call_ms:.1f}",
            f"{self.p95_call_ms:.1f}",
            f"{self.median_cpu_ms:.1f}",
            f"{self.cpu_share:.2f}",
            f"{self.dispatch_cpu_ms:.2f}",
            str(self.builds),
            str(self.blas_threads),
        ]


HEADER = (
    "backend",
    "workers",
    "verified",
    "postures/s",
    "speed-up",
    "postures/s ÷ CPU share",
    "postures/s with start",
    "start [s]",
    "median call [ms]",
    "p95 call [ms]",
    "CPU per call [ms]",
    "workers' CPU share",
    "dispatch CPU [ms/posture]",
    "builds timed",
    "BLAS threads",
)


def family_jobs(family: str, n: int, seed: int, jit: bool) -> tuple[Job, list[Job]]:
    """The family's warm-up job (its problem 0) and its n timed jobs (problems 1..n),
    with generated C (``jit``: mode sync) or CasADi's virtual machine (mode off)."""
    problems = list(FAMILIES[family][1](n + 1, seed))
    for problem in problems:
        problem.solver_options = dataclasses.replace(
            problem.solver_options, codegen="sync" if jit else "off"
        )
    jobs = make_jobs(problems)
    return jobs[0], jobs[1:]


def _row(
    backend: str,
    workers: int,
    items: list[BatchItem],
    times: tuple[float, float, float],
    infos: list[WorkerInfo],
) -> ScalingRow:
    """A row from the items and ``times``: start and wall time, this process's CPU time in
    the timed part (the in-process row's solves subtracted) [s]."""
    start_s, wall_s, cpu_s = times
    calls = [1e3 * i.call_time_s for i in items]
    cpu = [i.cpu_time_s for i in items]
    n = len(items)
    return ScalingRow(
        backend=backend,
        workers=workers,
        n=n,
        verified=sum(i.result.success for i in items),
        start_s=start_s,
        wall_s=wall_s,
        rate=n / wall_s,
        cold_rate=n / (start_s + wall_s),
        median_call_ms=statistics.median(calls),
        p95_call_ms=percentile(calls, 0.95),
        median_cpu_ms=1e3 * statistics.median(cpu),
        cpu_share=sum(cpu) / (workers * wall_s),
        dispatch_cpu_ms=1e3 * (cpu_s - (sum(cpu) if backend == "in-process" else 0.0)) / n,
        builds=sum(isinstance(i.result, Result) and i.result.build_time_s > 0 for i in items),
        blas_threads=max((t for info in infos for _, t in info.blas_threads), default=0),
    )


def in_process(warm: Job, jobs: list[Job]) -> ScalingRow:
    """The n problems solved one after the other in this process (no pool)."""
    t0 = time.perf_counter()
    solve_job(warm)
    t1, cpu1 = time.perf_counter(), time.process_time()
    items = [solve_job(job) for job in jobs]
    t2, cpu2 = time.perf_counter(), time.process_time()
    return _row("in-process", 1, items, (t1 - t0, t2 - t1, cpu2 - cpu1), [worker_info()])


def on_backend(backend: str, workers: int | None, warm: Job, jobs: list[Job]) -> ScalingRow:
    """The n problems on ``workers`` warm workers of ``backend`` (None: its default)."""
    t0 = time.perf_counter()
    pool = open_backend(backend, workers, warm=[warm])
    try:
        pool.ready()
        t1, cpu1 = time.perf_counter(), time.process_time()
        items = list(run_jobs(pool, jobs))
        t2, cpu2 = time.perf_counter(), time.process_time()
        infos = pool.ready()
    finally:
        pool.close()
    return _row(backend, pool.workers, items, (t1 - t0, t2 - t1, cpu2 - cpu1), infos)


def batch_scaling(
    family: str = DEFAULT_FAMILY,
    n: int = 500,
    seed: int = 0,
    jit: bool = False,
    ray: bool = True,
    done: Callable[[ScalingRow], None] | None = None,
) -> list[ScalingRow]:
    """The rows: in-process, local with 1, 2 and os.cpu_count() workers, Ray on every CPU of
    its instance (a local one of os.cpu_count() CPUs unless this process joined one: when
    ``ray``); each speed-up is over the 1-worker local row."""
    warm, jobs = family_jobs(family, n, seed, jit)
    counts = sorted({1, min(2, os.cpu_count() or 1), os.cpu_count() or 1})
    plans: list[tuple[str, int | None]] = [("local", w) for w in counts]
    plans += [("ray", None)] if ray else []
    rows = [in_process(warm, jobs)]
    if done is not None:
        done(rows[0])
    for backend, workers in plans:
        try:
            rows.append(on_backend(backend, workers, warm, jobs))
        except InputError as exc:  # Ray cannot start here: the other rows stand
            print(f"{backend}: no row: {exc}")
            continue
        if done is not None:
            done(rows[-1])
    base = next(r.rate for r in rows if r.backend == "local" and r.workers == 1)
    return [dataclasses.replace(r, speedup=r.rate / base) for r in rows]


def machine_line() -> str:
    """Where and when: the date, the CPU, the cores and the load averages (1, 5, 15 min)."""
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"{date.today().isoformat()}, {_cpu()}, {os.cpu_count()} cores, load average {load}"


def _cpu() -> str:
    """The CPU's model name (Linux), else the machine's architecture."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def table(rows: list[ScalingRow]) -> list[str]:
    """The rows as a Markdown table."""
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    return lines + ["| " + " | ".join(r.cells()) + " |" for r in rows]
