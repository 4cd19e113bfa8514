"""08 — A batch on every core: ``pg.solve_many``.

Problems (files, dicts or Problem objects) are solved on worker processes, the answers in
input order; a problem that cannot be read is a ``BatchError`` in its place, not a crash.
On a cluster, ``backend="ray"`` (pip install 'posturegen[ray]').
Run: python examples/08_batch.py
"""

from __future__ import annotations

import copy
from pathlib import Path

import posturegen as pg
from posturegen.io.problem_file import read_yaml

HERE = Path(__file__).resolve().parent


def main(n: int = 6, workers: int = 2) -> list:
    data = read_yaml(HERE / "problems" / "stand_reach.yaml")
    problems: list = []
    for i in range(n):
        d = copy.deepcopy(data)
        d["tasks"][0]["target"] = [0.35 + 0.02 * i, -0.35, 0.8 + 0.04 * i]
        problems.append(d)
    broken = copy.deepcopy(data)
    broken["tasks"][0]["frame"] = "right_paw"  # no such frame
    problems.append(broken)

    answers = pg.solve_many(problems, workers=workers)
    for i, answer in enumerate(answers):
        if isinstance(answer, pg.BatchError):
            print(f"{i}: not solved: {answer}")
        else:
            print(f"{i}: verified {answer.success}, {1e3 * answer.solve_time_s:.0f} ms")
    return answers


if __name__ == "__main__":
    main()
