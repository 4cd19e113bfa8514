"""07 — Warm starts in a planner's loop with ``NearestStarts``.

A planner asks for many postures that differ a little (targets along a path). Each answer
starts from the verified solution whose parameters (targets, contact poses) are nearest:
fewer iterations than from the initial posture. Every answer is still re-checked.
Run: python examples/07_warm_starts.py
"""

from __future__ import annotations

import copy
import statistics
from pathlib import Path

import numpy as np

import posturegen as pg
from posturegen.io.problem_file import read_yaml
from posturegen.solver.starts import NearestStarts

HERE = Path(__file__).resolve().parent


def queries(n: int, seed: int) -> list[pg.Problem]:
    """n reach targets of the right gripper on a 20 cm arc in front of TALOS."""
    data = read_yaml(HERE / "problems" / "stand_reach.yaml")
    rng = np.random.default_rng(seed)
    out = []
    for angle in np.sort(rng.uniform(-0.4, 0.4, n)):
        d = copy.deepcopy(data)
        d["tasks"][0]["target"] = [0.4 + 0.1 * np.cos(angle), -0.35 + 0.2 * angle, 0.9]
        out.append(pg.problem_from_dict(d))
    return out


def main(n: int = 12) -> tuple[float, float]:
    cold = [pg.solve(q).iterations for q in queries(n, seed=1)]
    starts = NearestStarts()
    warm = []
    for query in queries(n, seed=1):
        answer = pg.solve(query, start=starts.nearest(query))  # None for the first query
        assert answer.success, answer.message
        starts.add(query, answer)  # kept only when verified
        warm.append(answer.iterations)
    print(f"median iterations: {statistics.median(cold)} from the initial posture, "
          f"{statistics.median(warm)} from the nearest solution")  # fmt: skip
    return statistics.median(cold), statistics.median(warm)


if __name__ == "__main__":
    main()
