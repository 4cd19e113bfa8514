"""09 — Planning: a contact sequence found by search, no stage list.

``pg.plan`` searches the stances from the scene's start to its goal (both soles on the top
step): each transition adds or removes one contact, each stance is a posture solved and
verified. It writes the sequence (``sequence.json``, a posture file per stage) and
``plan.json`` (where the time went); ``write_figures`` adds what ``posturegen plan`` shows:
``plan.html`` (the 3-D viewer, a slider over the stances) and ``plan.png`` (a contact sheet).
TALOS, stairs of 2 steps. The same from the shell:
``posturegen plan stairs --robot talos --steps 2 --out out/plan``.
Run: python examples/09_plan_stairs.py [OUT_DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

import posturegen as pg
from posturegen.planner import Budget
from posturegen.planner.command import write_figures


def main(out: Path) -> pg.PlanReport:
    report = pg.plan("stairs", out, robot="talos", steps=2, budget=Budget(nodes=20))
    assert report.success, report.summary
    for stance in report.summary["stances"]:
        print(stance)
    print(f"{len(report.sequence.stages)} stages, every posture verified; written to {out}")
    stats = report.stats  # the search: transitions tried, postures solved, time [s]
    print(
        f"{stats.tried} transitions tried, {stats.postures} postures solved, {stats.time_s:.1f} s"
    )
    print(f"removals, each unloaded exactly where the contact was: {stats.unloads}")
    for line in write_figures(out):  # plan.html and plan.png
        print(line)
    return report


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/example09"))
