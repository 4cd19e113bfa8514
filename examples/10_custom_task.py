"""10 — A task of your own: one class, registered, works like a built-in one.

``HandsLevel`` keeps both grippers at the same height (within ``tolerance``) and at most
``max_gap`` apart: two blocks of rows. It writes its error once against ``Frames``; the same
code declares the program's rows (CasADi) and lets ``verify`` re-check a posture
(Pinocchio). Registered, it is read from problem files, written to posture files and
re-checked by ``posturegen verify``.
Run: python examples/10_custom_task.py
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import yaml

import posturegen as pg
from posturegen.terms.tasks import Field, Frames, Task


@pg.register_task
@dataclass
class HandsLevel(Task):
    """z_left - z_right = 0 [m] and |p_left - p_right| <= max_gap [m]."""

    kind: ClassVar[str] = "hands_level"  # its "type" in problem files
    fields: ClassVar[dict[str, Field]] = {
        "left": Field("frame", "the left hand's frame"),
        "right": Field("frame", "the right hand's frame"),
        "max_gap": Field("number", "[m] the largest distance between the hands", default=0.5),
    }

    left: str
    right: str
    max_gap: float = 0.5

    def subject(self) -> str:
        return f"{self.left}-{self.right}"

    def errors(self, f: Frames) -> dict:
        p_left, p_right = f.position(self.left), f.position(self.right)
        return {"level": p_left[2] - p_right[2], "gap": f.norm(p_left - p_right)}

    def limits(self) -> dict:
        return {"gap": (0.0, self.max_gap)}  # "level" is an equality: 0


PROBLEM = """
robot: talos
surfaces:
  - {name: ground, position: [0, 0, 0], rpy: [0, 0, 0],
     vertices: [[-1, -1], [1, -1], [1, 1], [-1, 1]]}
contacts:
  - {robot_patch: left_sole, surface: ground, type: fixed, position: [0.0, 0.1], yaw: 0.0}
  - {robot_patch: right_sole, surface: ground, type: fixed, position: [0.0, -0.1], yaw: 0.0}
tasks:
  - {type: position, frame: gripper_right_base_link, target: [0.4, -0.25, 1.1]}
  - {type: hands_level, left: gripper_left_base_link, right: gripper_right_base_link,
     max_gap: 0.35, tolerance: 0.001}
options: {initial: half_sitting, self_collision: true}
"""


def main() -> pg.Result:
    problem = pg.problem_from_dict(yaml.safe_load(PROBLEM))
    result = pg.solve(problem)
    assert result.success, result.message
    written = result.posture["tasks"][1]
    print("written:", written)
    report = pg.verify_posture(result.posture, problem.robot.model)  # re-reads the entry
    print("verified:", report.ok, [c.name for c in report.checks if c.name == "tasks"])
    return result


if __name__ == "__main__":
    main()
