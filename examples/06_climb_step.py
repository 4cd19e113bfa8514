"""06 — One climb step with ``next_problem`` (the paper's sec. IV-E).

TALOS stands on the ground and puts its right foot on a step, found as a non-inclusive
contact (``support``). ``next_problem`` then fixes the foot where it was found (its forces on
the vertices of the sole ∩ step) and releases the left foot: TALOS stands on the step alone,
its previous posture as the start.
Run: python examples/06_climb_step.py
"""

from __future__ import annotations

import numpy as np

import posturegen as pg
from posturegen.climb.stance import next_problem

GROUND = {"name": "ground", "position": [0, 0, 0], "rpy": [0, 0, 0],
          "vertices": [[-1, -1], [0.15, -1], [0.15, 1], [-1, 1]]}  # fmt: skip
STEP = {"name": "step", "position": [0.33, 0, 0.1], "rpy": [0, 0, 0],
        "vertices": [[-0.15, -0.4], [0.15, -0.4], [0.15, 0.4], [-0.15, 0.4]]}  # fmt: skip


def main() -> list[pg.Result]:
    start = pg.problem_from_dict(
        {
            "robot": "talos",
            "surfaces": [GROUND, STEP],
            "contacts": [
                {
                    "robot_patch": "left_sole",
                    "surface": "ground",
                    "type": "fixed",
                    "position": [0.0, 0.1],
                    "yaw": 0.0,
                },
                {
                    "robot_patch": "right_sole",
                    "surface": "step",
                    "type": "support",
                    "yaw_range": [-0.2, 0.2],
                },
            ],  # fmt: skip
            "options": {"initial": "half_sitting", "self_collision": True},
        }
    )
    touch = pg.solve(start)
    assert touch.success, touch.message
    # stage 2: the right foot fixed where it touched, the left foot released
    on_right = next_problem(start, touch, fix="right_sole", release="left_sole")
    shift = pg.solve(on_right)
    assert shift.success, shift.message
    print("on the right foot alone:", np.round(shift.q[:3], 3))
    worst = max(c.ratio for c in shift.verification.checks)
    print(f"verified; the worst check at {worst:.2g} of its tolerance")
    return [touch, shift]


if __name__ == "__main__":
    main()
