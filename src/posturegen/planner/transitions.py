"""The problems of a transition (paper sec. IV-E), as problem-file dicts.

Adding patch p on surface s to stance S takes two postures: ``touch`` (S bears the weight, p
rests on s as a floating geometric contact, bearing no force: the union of both stances with
the new contact unloaded; a soft task guides p towards its target, its ellipse options come
from the rules) and ``hold`` (S + p, p fixed where touch realized it, its forces at the
vertices of the intersection of both polygons: the new stance holds alone). Removing p takes
one, ``unload``: S − p bears the weight while p still rests exactly where it was (a fixed
contact ``unloaded``: its pose rows, no force): that posture is both the union with p unloaded
and the new stance holding alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..climb.sequence import stage_problem_dict
from ..model.robot import Robot
from ..solver.problem import Problem
from ..solver.solve import Result
from .goal import Goal
from .node import Action, Node
from .rules import Rules

GUIDE_WEIGHT = 1.0  # soft task weight·|p - target|²/(0.1 m)² pulling a new contact's frame
# [iterations] an exact unload's call. Measured 2026-12-04 on the four shipped plans (stairs
# of 4 steps, ATLAS and Talos; both ladders, HRP-2): the verified ones took 9-299; the failed
# ones stopped at this bound, and the soft unload that used to follow them (the patch held by
# a stiff soft task, drifting up to 54 mm) took 2444-4508 iterations, 13-36 s on the virtual
# machine, and verified one of three: the search tries another transition instead
EXACT_UNLOAD_ITER = 300


def _keep(name: str, mu: float | None = None, grip: float = 0.0) -> dict[str, Any]:
    out: dict[str, Any] = {"name": name, "type": "keep"}
    if mu is not None:
        out["mu"] = mu
    if grip > 0:
        out["grip"] = grip
    return out


def _frame_task(frame: str, target: np.ndarray, weight: float) -> dict[str, Any]:
    return {
        "type": "position",
        "frame": frame,
        "target": [float(v) for v in target],
        "weight": weight,
    }


def goal_tasks(goal: Goal) -> list[dict[str, Any]]:
    """The goal frame's soft task (none for a contacts goal or a zero weight)."""
    if goal.frame is None or goal.point is None or goal.weight <= 0:
        return []
    return [_frame_task(goal.frame, np.array(goal.point), goal.weight)]


def frame_target(robot: Robot, patch: str, target: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Where the patch's frame is when the patch's origin is at ``target`` on a surface of
    outward ``normal`` (the frame taken to sit along the normal from its patch)."""
    offset = float(np.linalg.norm(robot.patch(patch).T_frame_patch.translation))
    return target + offset * normal


def touch_stage(
    seq: Mapping[str, Any], node: Node, action: Action, rules: Rules, goal: Goal
) -> dict[str, Any]:
    """The problem dict of the touch posture of ``action`` (an add) from ``node``."""
    robot = node.last.problem.robot
    surface = node.last.problem.scene.surface(action.surface)
    contact = {
        "name": action.patch,
        "robot_patch": action.patch,
        "surface": action.surface,
        "type": "geometric",
        **dict(rules.patches[action.patch].contact),
    }
    target = frame_target(robot, action.patch, np.array(action.target), surface.normal)
    stage = {
        "name": f"touch: {action.label()}",
        "contacts": [*(_keep(n) for n in node.contacts.values()), contact],
        "tasks": [
            _frame_task(robot.patch(action.patch).frame, target, GUIDE_WEIGHT),
            *goal_tasks(goal),
        ],
    }
    return stage_problem_dict(dict(seq), stage, node.depth + 1, node.last.problem, node.q)


def hold_stage(
    seq: Mapping[str, Any],
    node: Node,
    action: Action,
    touch: tuple[Problem, Result],
    rules: Rules,
    goal: Goal,
) -> dict[str, Any]:
    """The problem dict of the hold posture: every contact of the touch posture fixed where
    it was realized (stance.next_problem's rule: the new one's forces at the vertices of the
    intersection), warm-started from it."""
    problem, result = touch
    rule = rules.patches[action.patch]
    stage = {
        "name": action.label(),
        "contacts": [
            *(_keep(n) for n in node.contacts.values()),
            _keep(action.patch, rule.mu, rule.grip),
        ],
        "tasks": goal_tasks(goal),
    }
    return stage_problem_dict(dict(seq), stage, node.depth + 1, problem, result.q)


def lift_stage(seq: Mapping[str, Any], node: Node, action: Action, goal: Goal) -> dict[str, Any]:
    """The problem dict of a removal under ``release: lift``: the other contacts alone, the
    patch free (the union with it unloaded is not checked)."""
    stage = {
        "name": f"lift: {action.label()}",
        "contacts": [_keep(n) for p, n in node.contacts.items() if p != action.patch],
        "tasks": goal_tasks(goal),
    }
    return stage_problem_dict(dict(seq), stage, node.depth + 1, node.last.problem, node.q)


def unload_stage(seq: Mapping[str, Any], node: Node, action: Action, goal: Goal) -> dict[str, Any]:
    """The problem dict of the unload posture of ``action`` (a remove) from ``node``: the
    other contacts bear the weight, the removed one kept exactly where it is, bearing nothing
    (a fixed contact ``unloaded``: its pose rows, no force)."""
    name = node.contacts[action.patch]
    solver = dict((seq.get("options") or {}).get("solver") or {})
    solver["max_call_iter"] = min(
        int(solver.get("max_call_iter", EXACT_UNLOAD_ITER)), EXACT_UNLOAD_ITER
    )
    stage = {
        "name": f"unload: {action.label()}",
        "contacts": [
            *(_keep(n) for p, n in node.contacts.items() if p != action.patch),
            {**_keep(name), "unloaded": True},
        ],
        "tasks": goal_tasks(goal),
        "options": {"solver": solver},
    }
    return stage_problem_dict(dict(seq), stage, node.depth + 1, node.last.problem, node.q)
