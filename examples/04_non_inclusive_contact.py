"""04 — Non-inclusive against inclusive: a foot on a step shorter than the foot.

The paper's contribution (Brossette et al. 2014, sec. IV): instead of forcing the robot's
patch inside the surface (``inclusive``: every vertex of the sole on the step), an ellipse
must lie inside both polygons (``support``: 5 variables, one row per edge of each), so the
foot may overhang the step. TALOS' sole is 21 cm long; the step is 12 cm deep. Inclusive
cannot hold it; non-inclusive finds where the sole rests and the forces on the intersection.
Run: python examples/04_non_inclusive_contact.py
"""

from __future__ import annotations

import numpy as np

import posturegen as pg
from posturegen.climb.stance import next_problem

STEP = {"name": "step", "position": [0.3, -0.1, 0.12], "rpy": [0, 0, 0],
        "vertices": [[-0.06, -0.25], [0.06, -0.25], [0.06, 0.25], [-0.06, 0.25]]}  # fmt: skip
GROUND = {"name": "ground", "position": [0, 0, 0], "rpy": [0, 0, 0],
          "vertices": [[-1, -1], [0.2, -1], [0.2, 1], [-1, 1]]}  # fmt: skip


def problem(step_contact: str) -> pg.Problem:
    return pg.problem_from_dict(
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
                    "type": step_contact,
                    "yaw_range": [-0.3, 0.3],
                },
            ],  # fmt: skip
            "options": {"initial": "half_sitting"},
        }
    )


def main() -> tuple[pg.Result, pg.Result]:
    inclusive = pg.solve(problem("inclusive"))
    print("inclusive:", inclusive.success, "-", inclusive.message)

    support = pg.solve(problem("support"))
    assert support.success, support.message
    contact = next(
        c for c in support.posture["contacts"] if c["robot_patch"]["name"] == "right_sole"
    )
    ellipse = contact["ellipse"]
    print("non-inclusive: verified; ellipse radii [m]", np.round(ellipse["radii"], 3))
    forces = support.forces["right_sole"]
    print(f"right sole: {len(forces)} force points, {sum(f.force[2] for f in forces):.0f} N up")

    # sec. IV-E: the contact found becomes fixed in the next posture, its forces at the
    # vertices of the intersection of the sole and the step
    fixed = pg.solve(next_problem(problem("support"), support, fix="right_sole"))
    print("fixed where it was found:", fixed.success)
    return inclusive, support


if __name__ == "__main__":
    main()
