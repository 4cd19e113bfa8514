"""02 — A problem built in Python, with tasks from the library.

The same stance as example 01, written as a dict (the problem file's content), with four
tasks: the right gripper in a box, its palm facing down, the head's camera looking at the
gripper's box, and the centre of mass inside the feet's rectangle by 3 cm. Then the same
problem with task objects (``pg.tasks``) in place of the dicts.
Run: python examples/02_problem_in_python.py
"""

from __future__ import annotations

import dataclasses

import numpy as np

import posturegen as pg

BOX_MIN, BOX_MAX = [0.35, -0.45, 0.85], [0.5, -0.3, 1.0]  # [m] in world

PROBLEM = {
    "robot": "talos",
    "mu": 0.7,
    "surfaces": [{"name": "ground", "position": [0, 0, 0], "rpy": [0, 0, 0],
                  "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]}],
    "contacts": [
        {"robot_patch": "left_sole", "surface": "ground", "type": "fixed",
         "position": [0.0, 0.1], "yaw": 0.0},
        {"robot_patch": "right_sole", "surface": "ground", "type": "fixed",
         "position": [0.0, -0.1], "yaw": 0.0},
    ],
    "tasks": [
        {"type": "region", "frame": "gripper_right_base_link", "min": BOX_MIN, "max": BOX_MAX},
        {"type": "axis", "frame": "gripper_right_base_link", "axis": [0, 0, 1],
         "direction": [0, 0, -1], "weight": 1.0},  # soft: a cost, not a constraint
        {"type": "gaze", "frame": "rgbd_optical_frame", "axis": [0, 0, 1],
         "target": [0.42, -0.37, 0.92]},
        {"type": "com", "polygon": [[-0.1, -0.17], [0.15, -0.17], [0.15, 0.17], [-0.1, 0.17]],
         "margin": 0.03},
    ],
    "options": {"initial": "half_sitting", "self_collision": False},
}  # fmt: skip


def main() -> tuple[pg.Result, pg.Result]:
    problem = pg.problem_from_dict(PROBLEM)
    result = pg.solve(problem)
    assert result.success, result.message
    for task in result.posture["tasks"]:
        print(task["type"], "hard" if task["weight"] is None else f"soft, weight {task['weight']}")

    # the same tasks as objects: each is a dataclass; its keys are checked as a file's are
    tasks = [
        pg.tasks.RegionTask(frame="gripper_right_base_link", min=BOX_MIN, max=BOX_MAX),
        pg.tasks.AxisTask(
            frame="gripper_right_base_link", axis=[0, 0, 1], direction=[0, 0, -1], weight=1.0
        ),
        pg.tasks.GazeTask(frame="rgbd_optical_frame", axis=[0, 0, 1], target=[0.42, -0.37, 0.92]),
        pg.tasks.ComTask(polygon=PROBLEM["tasks"][3]["polygon"], margin=0.03),
    ]
    again = pg.solve(dataclasses.replace(problem, tasks=tasks))
    assert again.success
    print("same posture:", np.allclose(result.q, again.q, atol=1e-6))
    return result, again


if __name__ == "__main__":
    main()
