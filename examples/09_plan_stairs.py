"""09 — Planning: a contact sequence found by search, no stage list.

``pg.plan`` searches the stances from the scene's start to its goal (both soles on the top
step): each transition adds or removes one contact, each stance is a posture solved and
verified. It writes the sequence (``sequence.json``, a posture file per stage) and
``plan.json`` (where the time went). ATLAS, stairs of 2 steps.
Run: python examples/09_plan_stairs.py [OUT_DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

import posturegen as pg
from posturegen.planner import Budget


def main(out: Path) -> pg.PlanReport:
    report = pg.plan("stairs", out, robot="atlas", steps=2, budget=Budget(nodes=20))
    assert report.success, report.summary
    for stance in report.summary["stances"]:
        print(stance)
    print(f"{len(report.sequence.stages)} stages, every posture verified; written to {out}")
    return report


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/example09"))
