"""``posturegen.plan``: find a contact sequence from a start stance to a goal."""

from __future__ import annotations

import copy
import json
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import _fields as F
from ..climb.sequence import SequenceReport, stage_problem_dict
from ..errors import InputError
from ..io.problem_file import problem_from_dict, read_yaml
from ..model.robot import Robot
from ..solver.problem import Problem, with_sequence_method
from ..solver.solve import Result, own_learning
from .goal import Goal, parse_goal
from .heuristic import Heuristic
from .layout import goal_spots, regions
from .node import Node, Stage
from .output import plan_summary, plan_times, write_failed, write_sequence
from .quality import Quality
from .rules import Rules, default_rules, parse_rules, patch_positions
from .scenes import PLANS, default_goal, plan_scene, scene_rules
from .search import Budget, Progress, Search, Stats, frame_position
from .solver import RoundSolver

_SEQ_KEYS = ("robot", "mu", "surfaces", "obstacles", "friction", "costs", "options", "name")


@dataclass(frozen=True)
class PlanReport:
    """A plan's outcome: the sequence written, the search's statistics, the worst contact
    quality along the sequence, the goal and rules it used."""

    sequence: SequenceReport
    stats: Stats
    quality: Quality
    goal: Goal
    rules: Rules
    summary: dict[str, Any]

    @property
    def success(self) -> bool:
        """The goal was reached and every posture on the way verified."""
        return self.stats.reached and self.sequence.success


def _as_mapping(value: Any, field: str) -> Any:
    """A dict given as a dict, a YAML/JSON file path, or inline YAML text."""
    if value is None or isinstance(value, Mapping):
        return value
    if isinstance(value, str | Path) and Path(value).is_file():
        return read_yaml(value)
    if isinstance(value, str):
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            pass
    raise InputError(field, f"cannot read {value!r}", "give a mapping, or a YAML file's path")


def _source(
    source: Any, robot: str | None, steps: int | None
) -> tuple[dict[str, Any], dict[str, Any], str | None]:
    """(sequence dict of the scene, start stage, shipped scene name or None)."""
    if isinstance(source, str) and source in PLANS:
        seq = plan_scene(source, robot, steps)
        return seq, seq["stages"][0], source
    data = _as_mapping(source, "problem")
    if not isinstance(data, Mapping) or "contacts" not in data:
        raise InputError(
            "problem", "not a scene name nor a problem", f"use {', '.join(PLANS)} or a problem file"
        )
    if robot is not None:
        raise InputError("--robot", "a problem file names its robot", "drop --robot")
    seq = {k: copy.deepcopy(data[k]) for k in _SEQ_KEYS if k in data}
    seq.setdefault("name", "plan")
    return seq, {"name": "start", "contacts": copy.deepcopy(data["contacts"])}, None


def _start_problem(seq: Mapping[str, Any], stage: Mapping[str, Any]) -> tuple[dict, Problem]:
    """The start stance's problem dict and Problem (its robot, scene and contacts)."""
    data = stage_problem_dict(dict(seq), dict(stage), 0, None, None)
    return data, problem_from_dict(data)


def _start(seq: Mapping[str, Any], data: dict, problem: Problem, solver: RoundSolver) -> Node:
    """The start stance: its problem solved (each floating contact then fixed where it was
    realized, in a second posture)."""
    result = solver.solve([data], [problem])[0]
    if not isinstance(result, Result) or not result.success:
        why = getattr(result, "message", "")
        raise InputError("start", "the start stance holds no verified posture", why)
    stages = [Stage(str(data["name"]), data, problem, result)]
    if any(c.type != "fixed" for c in problem.contacts):
        keep = [{"name": c.name, "type": "keep"} for c in problem.contacts]
        data = stage_problem_dict(
            dict(seq), {"name": "start (fixed)", "contacts": keep}, 1, problem, result.q
        )
        problem = problem_from_dict(data)
        result = solver.solve([data], [problem])[0]
        if not isinstance(result, Result) or not result.success:
            why = getattr(result, "message", "")
            raise InputError("start", "the start stance, fixed, holds no verified posture", why)
        stages.append(Stage("start (fixed)", data, problem, result))
    key = frozenset((c.patch.name, c.surface.name) for c in problem.contacts)
    contacts = {c.patch.name: c.name for c in problem.contacts}
    return Node(key, contacts, tuple(stages), patch_positions(problem.robot, result.q))


def _heuristic(goal: Goal, rules: Rules, start: Node, robot: Robot) -> Heuristic:
    scene = start.last.problem.scene
    areas = regions(scene)
    frame = frame_position(goal.frame, start.q, robot)
    spots = goal_spots(goal, areas, start.positions, frame)
    return Heuristic(goal, areas, spots, 3 if rules.hands else 2)


def _inputs(
    seq: Mapping[str, Any], scene_name: str | None, problem: Problem, goal: Any, rules: Any
) -> tuple[Goal, Rules]:
    """The goal and rules, checked against the start problem's robot and scene."""
    model = problem.robot
    surfaces = list(problem.scene.surfaces)
    base = scene_rules(scene_name, seq, model) if scene_name else default_rules(model, surfaces)
    the_rules = parse_rules(_as_mapping(rules, "rules"), base)
    goal_value = _as_mapping(goal, "goal")
    if goal_value is None:
        if scene_name is None:
            raise InputError("goal", "missing", "give a goal: contacts, or frame and point")
        goal_value = default_goal(seq)
    frames = [f.name for f in model.model.frames]
    return parse_goal(goal_value, list(model.patches), surfaces, frames), the_rules


# A plan meets each program structure a few times: a structure whose library is on disk runs
# it, any other the virtual machine, and nothing is compiled (posturegen.solver.codegen, mode
# cached: there, the measurements).
PLAN_CODEGEN = "cached"


def _solver_options(seq: dict[str, Any], budget: Budget) -> None:
    """The stages' solver options: the budget's iterations per posture, PLAN_CODEGEN unless
    the scene or $POSTUREGEN_CODEGEN sets a mode, and SEQUENCE_METHOD unless a solver is
    named."""
    options = seq.setdefault("options", {})
    solver = dict(options.get("solver") or {})
    if budget.posture_iterations is not None:
        F.integer(budget.posture_iterations, "budget.posture_iterations", 1, "give 1 or more")
        solver["max_call_iter"] = budget.posture_iterations
    if not os.environ.get("POSTUREGEN_CODEGEN") and not solver.get("jit"):
        solver.setdefault("codegen", PLAN_CODEGEN)
    options["solver"] = with_sequence_method(solver)


def plan(
    source: Any,
    out: str | Path,
    goal: Any = None,
    rules: Any = None,
    robot: str | None = None,
    steps: int | None = None,
    budget: Budget | None = None,
    workers: int = 1,
    progress: Progress | None = None,
) -> PlanReport:
    """Search a contact sequence from ``source``'s stance to ``goal`` and write it to ``out``.

    ``source``: a shipped scene's name (``stairs``, ``ladder-inclined``, ``ladder-vertical``;
    ``robot`` and ``steps`` as for ``climb``) or a problem (dict or file) whose contacts are
    the start stance; ``goal``/``rules``: dicts or files (posturegen.planner.goal / .rules;
    a scene has defaults); ``workers`` > 1 keeps that many transitions in flight on the batch
    pool (posturegen.planner.search)."""
    t0 = time.perf_counter()
    seq, start_stage, scene_name = _source(source, robot, steps)
    budget = budget or Budget()
    _solver_options(seq, budget)
    data, problem = _start_problem(seq, start_stage)
    the_goal, the_rules = _inputs(seq, scene_name, problem, goal, rules)
    # the plan learns its own active sets: its outcome is not that of the process's history
    with own_learning(), RoundSolver(workers) as solver:
        start = _start(seq, data, problem, solver)
        model = problem.robot
        heur = _heuristic(the_goal, the_rules, start, model)
        search = Search(seq, heur, the_rules, solver, budget, progress)
        start.extra["frame"] = frame_position(the_goal.frame, start.q, model)
        start.h = heur.h(start.key, start.positions, start.extra["frame"])
        best, stats = search.run(start)
    t_files = time.perf_counter()
    path = best.path()
    report, quality = write_sequence(seq, path, stats.reached, Path(out))
    write_failed(stats, Path(out))
    goal_d, rules_d = the_goal.to_dict(), the_rules.to_dict()
    times = plan_times(time.perf_counter() - t0, time.perf_counter() - t_files, solver.timing)
    summary = plan_summary(seq, goal_d, rules_d, budget, stats, path, quality, times)
    (Path(out) / "plan.json").write_text(json.dumps(summary, indent=1))
    return PlanReport(report, stats, quality, the_goal, the_rules, summary)
