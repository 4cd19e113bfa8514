"""05 — Collision avoidance: the robot's own links and a box in the scene.

The right gripper reaches across the body, next to a box standing in front of the robot.
``self_collision`` keeps every pair of links (sphere proxies fitted to the meshes, up to 1 cm
outside them) apart by ``collision_margin``; obstacles are avoided the same way. The posture
is then re-checked on the real collision meshes (coal), every pair, none skipped.
Run: python examples/05_collision_avoidance.py
"""

from __future__ import annotations

import copy
from pathlib import Path

import posturegen as pg
from posturegen.io.problem_file import read_yaml
from posturegen.solver.inspection import describe

HERE = Path(__file__).resolve().parent


def main() -> pg.Result:
    data = read_yaml(HERE / "problems" / "stand_reach.yaml")
    data["tasks"][0]["target"] = [0.3, 0.05, 0.95]  # [m] in front of the chest, to the left
    data["obstacles"] = [{"name": "box", "box": [0.2, 0.3, 0.8], "position": [0.55, -0.3, 0.4],
                          "rpy": [0, 0, 0]}]  # fmt: skip
    data["options"] = {"initial": "half_sitting", "self_collision": True, "collision_margin": 0.005}

    problem = pg.problem_from_dict(data)
    print(describe(problem))  # the collision rows the first run will have
    result = pg.solve(problem)
    assert result.success, result.message
    for check in result.verification.checks:
        if "collision" in check.name or "distance" in check.name:
            print(f"{check.name}: {check.value:.4g} (tolerance {check.tolerance:g})")
    for note in result.verification.notes:
        print("note:", note)

    # without avoidance the arm takes the short way, through the body: not verified as
    # collision-free (the posture file then has no collision entry and says so)
    free = copy.deepcopy(data)
    free["options"]["self_collision"] = False
    free["options"]["environment_collision"] = False
    crossing = pg.solve(pg.problem_from_dict(free))
    print(
        "without avoidance:", crossing.success, "collision checked:", crossing.posture["collision"]
    )
    return result


if __name__ == "__main__":
    main()
