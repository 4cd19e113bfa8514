"""What a batch shows and leaves: the progress bar (stderr), the summary table, the files
(a posture file per problem, ``batch.json`` the index)."""

from __future__ import annotations

import json
import statistics
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from ..solver.runs import _IPOPT_OK
from ..solver.solve import Result
from .jobs import BatchError, BatchItem

INDEX_FILE = "batch.json"
INDEX_SCHEMA = "posturegen.batch/1"
VERIFIED = "verified"


def category(answer: Result | BatchError) -> str:
    """The summary's row of one answer: ``verified``; a failed solve by its main cause
    (``blocked: task``, ``blocked: torque``... when diagnosed), by the check that rejected
    IPOPT's posture (``re-check: torque limits``) or by IPOPT's status; a problem without a
    Result by its BatchError status (``input error``, ``error``, ``worker crashed``)."""
    if isinstance(answer, BatchError):
        return answer.status
    if answer.success:
        return VERIFIED
    if answer.status in _IPOPT_OK:
        failures = answer.verification.failures
        return f"re-check: {failures[0].name}" if failures else "re-check"
    diagnosis = answer.posture.get("diagnosis")
    if isinstance(diagnosis, dict):
        causes = diagnosis.get("causes") or []
        return f"blocked: {causes[0]['kind']}" if causes else "no constraint blocks it"
    return f"{'SQP' if answer.method == 'sqp' else 'IPOPT'}: {answer.status}"


def percentile(values: Sequence[float], q: float) -> float:
    """The q-quantile (0..1) by linear interpolation; nan for no values."""
    if not values:
        return float("nan")
    xs = sorted(values)
    pos = q * (len(xs) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


@dataclass(frozen=True)
class Summary:
    """Counts by category, times of the whole calls in the workers and of IPOPT [s], the
    batch's wall time [s] (``start_s`` of it starting the workers) and its rate
    [postures/s]."""

    n: int
    counts: tuple[tuple[str, int], ...]  # verified first, then the failures, most first
    call_times_s: tuple[float, ...]
    solve_times_s: tuple[float, ...]
    wall_s: float
    workers: int
    backend: str
    start_s: float = 0.0

    @classmethod
    def of(
        cls,
        items: Sequence[BatchItem],
        wall_s: float,
        workers: int,
        backend: str,
        start_s: float = 0.0,
    ) -> Summary:
        counts = Counter(category(i.result) for i in items)
        ordered = [(VERIFIED, counts.pop(VERIFIED, 0)), *counts.most_common()]
        return cls(
            n=len(items),
            counts=tuple(ordered),
            call_times_s=tuple(i.call_time_s for i in items if i.worker),
            solve_times_s=tuple(
                i.result.solve_time_s for i in items if isinstance(i.result, Result)
            ),
            wall_s=wall_s,
            workers=workers,
            backend=backend,
            start_s=start_s,
        )

    @property
    def verified(self) -> int:
        """Problems with a verified posture."""
        return dict(self.counts)[VERIFIED]

    @property
    def rate(self) -> float:
        """Postures (every answer) per second of wall time."""
        return self.n / self.wall_s if self.wall_s > 0 else float("nan")

    def lines(self) -> list[str]:
        """The summary table."""
        out = [
            f"batch: {self.n} problems, {self.workers} workers ({self.backend}), "
            f"{self.wall_s:.1f} s ({self.start_s:.1f} s to start them), "
            f"{self.rate:.1f} postures/s",
        ]
        for name, count in self.counts:
            label = name if name == VERIFIED else f"failed, {name}"
            out.append(f"  {label:<44} {count:>6}  {100 * count / max(self.n, 1):5.1f} %")
        for label, times in (("whole call", self.call_times_s), ("IPOPT", self.solve_times_s)):
            med, p95 = statistics.median(times) if times else float("nan"), percentile(times, 0.95)
            out.append(f"  {label + ' [ms]':<44} median {1e3 * med:7.1f}  p95 {1e3 * p95:7.1f}")
        return out

    def to_dict(self) -> dict[str, Any]:
        """The index file's ``summary``."""
        return {
            "problems": self.n,
            "counts": dict(self.counts),
            "wall_s": self.wall_s,
            "start_s": self.start_s,
            "postures_per_s": self.rate,
            "workers": self.workers,
            "backend": self.backend,
            "median_call_s": statistics.median(self.call_times_s) if self.call_times_s else None,
            "p95_call_s": percentile(self.call_times_s, 0.95) if self.call_times_s else None,
        }


def write_posture(item: BatchItem, out: Path) -> str | None:
    """Write the item's posture file (``NAME.json``, also for a failed solve: success false and
    its diagnosis); None when there is no posture (a BatchError)."""
    if isinstance(item.result, BatchError):
        return None
    return item.result.write(out / f"{item.name}.json").name


def index_entry(item: BatchItem, posture_file: str | None, source: str) -> dict[str, Any]:
    """One problem's line of the index file."""
    r = item.result
    solved = isinstance(r, Result)
    return {
        "index": item.index,
        "name": item.name,
        "source": source,
        "posture": posture_file,
        "success": r.success,
        "category": category(r),
        "status": r.status,
        "message": r.message,
        "diagnosis": (r.diagnosis or None) if solved else None,
        "iterations": r.iterations if solved else None,
        "solve_time_s": r.solve_time_s if solved else None,
        "call_time_s": item.call_time_s,
        "worker": item.worker or None,
    }


def write_index(out: Path, entries: list[dict[str, Any]], summary: Summary) -> Path:
    """``DIR/batch.json``: every problem in input order, and the summary."""
    path = out / INDEX_FILE
    doc = {"schema": INDEX_SCHEMA, "summary": summary.to_dict(), "problems": entries}
    path.write_text(json.dumps(doc, indent=1))
    return path


class Progress:
    """A progress bar on ``stream`` (default: sys.stderr) with the rate: redrawn in place on a
    terminal (at most 10 times a second), else a line every 5 s and at the end."""

    def __init__(self, total: int, stream: TextIO | None = None, quiet: bool = False) -> None:
        self.total, self.quiet = total, quiet
        self.stream = stream if stream is not None else sys.stderr
        self.done = self.failed = 0
        self.t0 = self._shown = time.perf_counter()
        self.tty = bool(getattr(stream, "isatty", lambda: False)())

    def update(self, item: BatchItem) -> None:
        """Count one answer; redraw when due."""
        self.done += 1
        self.failed += not item.result.success
        now = time.perf_counter()
        if self.done == self.total or now - self._shown >= (0.1 if self.tty else 5.0):
            self._shown = now
            self._draw(now)

    def line(self, now: float) -> str:
        """The bar: ``[####....] 120/500  118 ok  2 failed  61.3 postures/s  eta 6 s``."""
        elapsed = max(now - self.t0, 1e-9)
        rate = self.done / elapsed
        filled = round(24 * self.done / max(self.total, 1))
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        return (
            f"[{'#' * filled}{'.' * (24 - filled)}] {self.done}/{self.total}  "
            f"{self.done - self.failed} ok  {self.failed} failed  {rate:.1f} postures/s  "
            f"eta {eta:.0f} s"
        )

    def clear(self) -> None:
        """Erase the bar on a terminal (before another line is printed there)."""
        if self.tty and not self.quiet:
            print(f"\r{'':<90}\r", end="", file=self.stream, flush=True)

    def _draw(self, now: float) -> None:
        if self.quiet:
            return
        end = "\n" if (not self.tty or self.done == self.total) else ""
        text = f"\r{self.line(now):<90}" if self.tty else self.line(now)
        print(text, end=end, file=self.stream, flush=True)
