"""``posturegen batch``: problems in, a folder of posture files out, with a progress bar and
the summary table."""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, TextIO

from .backends import open_backend
from .jobs import BatchItem, make_jobs
from .report import Progress, Summary, index_entry, write_index, write_posture
from .schedule import run_jobs


def _source(problem: Any) -> str | None:
    """What the index file says a problem came from: its file, else nothing."""
    return str(problem) if isinstance(problem, str | Path) else None


def batch_to_dir(
    problems: list[Any],
    out: Path,
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    quiet: bool = False,
    stream: TextIO | None = None,
) -> Summary:
    """Solve ``problems`` (diagnosing failures, as ``posturegen solve``), write each posture
    file ``OUT/NAME.json`` as it comes and ``OUT/batch.json`` at the end; the progress bar
    goes to ``stream`` (default: sys.stderr), the workers' warnings (``NAME: message``) to
    ``warnings``. The wall time counts the workers' start (``start_s``: until every worker
    is up)."""
    t0 = time.perf_counter()
    jobs = make_jobs(problems)
    pool = open_backend(backend, workers, address, diagnose=True)
    out.mkdir(parents=True, exist_ok=True)
    items: list[BatchItem] = []
    entries: dict[int, dict[str, Any]] = {}
    try:
        pool.ready()
        started = time.perf_counter()
        progress = Progress(len(jobs), stream, quiet)
        for item in run_jobs(pool, jobs):
            items.append(item)
            posture = write_posture(item, out)
            entries[item.index] = index_entry(item, posture, _source(problems[item.index]))
            if item.warnings:
                progress.clear()
            for category, message in item.warnings:
                warnings.warn(f"{item.name}: {message}", category, stacklevel=2)
            progress.update(item)
    finally:
        pool.close()
    wall = time.perf_counter() - t0
    summary = Summary.of(items, wall, pool.workers, backend, started - t0)
    write_index(out, [entries[i] for i in sorted(entries)], summary)
    return summary
