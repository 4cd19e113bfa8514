"""The results of ``posturegen bench`` as Markdown (``--markdown FILE``): one table row per
family, the machine and the date above it. A FILE holding the markers
``<!-- bench:start -->`` and ``<!-- bench:end -->`` (``bench-batch`` for ``--batch``) has
only the text between them replaced: ``posturegen bench --markdown docs/benchmarks.md``
regenerates the benchmark tables in place.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .families import FamilyReport
from .planner import PlannerReport

HEADER = (
    "family",
    "n",
    "verified",
    "IPOPT median [ms]",
    "call median [ms]",
    "call p90 [ms]",
    "first pass: call median (p90) [ms]",
    "iterations median",
    "nearest start: call median (p90) [ms], iterations",
)


def _ms(value: float) -> str:
    return f"{value:.1f}"


def family_row(r: FamilyReport) -> list[str]:
    """A family of ``posturegen bench`` (solved after a warm-up in the bench's process)."""
    return [
        f"`{r.family}`",
        str(r.n),
        f"{r.successes}/{r.n}",
        _ms(r.median_solve_ms),
        _ms(r.median_call_ms),
        _ms(r.p90_call_ms),
        "",
        f"{r.median_iterations:.0f}",
        "",
    ]


def planner_row(r: PlannerReport) -> list[str]:
    """A planner family: the steady state, the first pass of a fresh process, and the
    calls started from the nearest solution."""
    s, f, n = r.steady, r.first, r.nearest
    return [
        f"`{r.family}`",
        str(s.n),
        f"{s.verified}/{s.n}",
        _ms(s.median_solve_ms),
        _ms(s.median_call_ms),
        _ms(s.p90_call_ms),
        f"{_ms(f.median_call_ms)} ({_ms(f.p90_call_ms)}), {f.verified}/{f.n} verified",
        f"{s.median_iterations:.0f}",
        ""
        if n is None
        else f"{_ms(n.median_call_ms)} ({_ms(n.p90_call_ms)}), {n.median_iterations:.0f}",
    ]


def results_table(
    machine: str, jit: bool, families: list[FamilyReport], planner: list[PlannerReport]
) -> list[str]:
    """The Markdown lines: where and how the numbers were measured, then the table."""
    code = "generated C (`--jit`)" if jit else "CasADi's virtual machine"
    lines = [
        f"Measured on {machine}; {code}.",
        "",
        "| " + " | ".join(HEADER) + " |",
        "|" + "---|" * len(HEADER),
    ]
    rows = [family_row(r) for r in families] + [planner_row(r) for r in planner]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def write_markdown(path: str | Path, lines: list[str], marker: str = "bench") -> Path:
    """Write ``lines`` to ``path``, or between its ``<!-- {marker}:start -->`` and
    ``<!-- {marker}:end -->`` lines when it has them."""
    path = Path(path)
    start, end = f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"
    text = path.read_text() if path.exists() else ""
    if start in text or end in text:
        head, sep, rest = text.partition(start)
        _, sep2, tail = rest.partition(end)
        if not sep or not sep2:
            raise InputError(
                "--markdown", f"{path} has only one of {start} and {end}", "add the other"
            )
        path.write_text(head + start + "\n" + "\n".join(lines) + "\n" + end + tail)
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path
