"""Contact sequences (climbs): postures solved one stance after another (paper sec. IV-E).

A *sequence* is a scene (robot, surfaces, obstacles) and a list of *stages*. Each stage lists
its contacts like a problem file, plus one more contact type, ``keep``: the contact of the
previous stage with that name, frozen where it was realized, as a ``fixed`` contact whose
forces act at the vertices of the intersection of the two polygons. A contact that a stage
does not list is released. Each stage starts from the previous posture (warm start).

Every stage is written as a plain problem file (``NN-name.yaml``, solvable on its own with
``posturegen solve``) and its posture (``NN-name.json``); ``sequence.json`` indexes them::

    {"schema": "posturegen.sequence/1", "name": ..., "robot": ..., "success": bool,
     "stages": [{"name", "problem", "posture", "success", "message", "iterations",
                 "solve_time_s", "build_time_s", "wall_time_s"}, ...]}
"""

from __future__ import annotations

import copy
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from .. import _fields as F
from ..errors import InputError
from ..io.posture_file import write_posture
from ..io.problem_file import problem_from_dict
from ..io.sequence_file import write_sequence
from ..model.robot import load_robot
from ..solver.diagnose import diagnose as diagnosed
from ..solver.problem import Problem
from ..solver.solve import Result, solve
from .stance import frozen_pose

_SCENE_KEYS = ("robot", "mu", "surfaces", "obstacles", "friction", "costs")


@dataclass
class StageReport:
    """What one stage gave."""

    name: str
    problem_file: str
    posture_file: str
    result: Result
    wall_time_s: float
    diagnosis: str = ""  # for a failed stage: what blocks it (posturegen.solver.diagnose)

    def to_dict(self) -> dict[str, Any]:
        """The stage's entry of ``sequence.json``."""
        r = self.result
        return {
            "name": self.name,
            "problem": self.problem_file,
            "posture": self.posture_file,
            "success": r.success,
            "message": r.message,
            "diagnosis": self.diagnosis,
            "iterations": r.iterations,
            "solve_time_s": r.solve_time_s,
            "build_time_s": r.build_time_s,
            "wall_time_s": self.wall_time_s,
        }


@dataclass
class SequenceReport:
    """Every stage that ran; ``success`` when all stages were verified."""

    name: str
    stages: list[StageReport] = field(default_factory=list)
    planned: int = 0

    @property
    def success(self) -> bool:
        """True when every planned stage ran and was verified."""
        return len(self.stages) == self.planned and all(s.result.success for s in self.stages)


def placed_initial(robot_spec: Any, base: Any, field_name: str = "initial.base") -> list[float]:
    """The robot's default posture with its base moved to ``base`` = [x, y, yaw] (z unchanged;
    the first stage's contacts decide the height)."""
    robot = load_robot(robot_spec)
    b = F.vector(base, 3, field_name)
    F.angle(b[2], f"{field_name}[2]")
    q = robot.q_init.copy()
    q[0:2] = b[0:2]
    R0 = pin.Quaternion(q[3:7]).normalized().matrix()
    q[3:7] = pin.Quaternion(pin.utils.rotate("z", float(b[2])) @ R0).coeffs()
    return q.tolist()


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:40] or "stage"


def _contact_name(c: dict[str, Any]) -> str:
    return str(c.get("name", c.get("robot_patch")))


def _kept(
    c: dict[str, Any], fld: str, previous: Problem | None, q_prev: np.ndarray | None
) -> dict[str, Any]:
    """A ``keep`` contact as the ``fixed`` contact of the previous stage's realized pose."""
    if previous is None or q_prev is None:
        raise InputError(f"{fld}.type", "'keep' in the first stage", "give its pose: type fixed")
    name = _contact_name(c)
    old = {x.name: x for x in previous.contacts}.get(name)
    if old is None:
        raise InputError(
            f"{fld}.name",
            f"the previous stage has no contact '{name}'",
            f"keep one of: {', '.join(x.name for x in previous.contacts)}",
        )
    position, yaw = frozen_pose(old, previous.robot.model, q_prev)
    carried = ("name", "mu", "friction", "cop_margin", "unloaded", "grip")
    out = {k: v for k, v in c.items() if k in carried}
    out.setdefault("mu", float(old.mu))  # a kept contact keeps its friction coefficient
    if getattr(old, "grip", 0.0) > 0:  # and a hand's grip
        out.setdefault("grip", float(old.grip))
    if hasattr(old, "cop_margin"):  # and its CoP margin (else the stage's options give it)
        out.setdefault("cop_margin", float(old.cop_margin))
    out.update(
        {
            "robot_patch": old.patch.name,
            "surface": old.surface.name,
            "type": "fixed",
            "position": [float(position[0]), float(position[1])],
            "yaw": yaw,
        }
    )
    if "name" not in out and name != old.patch.name:
        out["name"] = name
    return out


def stage_problem_dict(
    seq: dict[str, Any],
    stage: dict[str, Any],
    index: int,
    previous: Problem | None,
    q_prev: np.ndarray | None,
) -> dict[str, Any]:
    """The plain problem dict of one stage (``keep`` resolved, initial posture set)."""
    fld = f"stages[{index}]"
    stage = F.require_mapping(stage, fld)
    F.check_keys(stage, fld, ["name", "contacts"], ["tasks", "options", "description"])
    contacts = stage["contacts"]
    if not isinstance(contacts, list) or not contacts:
        raise InputError(f"{fld}.contacts", "expected a non-empty list", "list the contacts")
    out: dict[str, Any] = {k: copy.deepcopy(seq[k]) for k in _SCENE_KEYS if k in seq}
    out["name"] = str(stage["name"])
    out["contacts"] = [
        _kept(c, f"{fld}.contacts[{i}]", previous, q_prev)
        if isinstance(c, dict) and c.get("type") == "keep"
        else copy.deepcopy(c)
        for i, c in enumerate(contacts)
    ]
    out["tasks"] = copy.deepcopy(stage.get("tasks", []))
    options = {**copy.deepcopy(seq.get("options", {}) or {}), **(stage.get("options") or {})}
    if q_prev is not None:
        options["initial"] = [float(v) for v in q_prev]
    elif "initial" in seq:
        init = F.require_mapping(seq["initial"], "initial")
        F.check_keys(init, "initial", ["base"], [])
        options["initial"] = placed_initial(seq["robot"], init["base"])
    out["options"] = options
    return out


def run_sequence(
    seq: dict[str, Any],
    out_dir: str | Path,
    progress: Callable[[int, int, str, StageReport | None], None] | None = None,
    stop_on_failure: bool = True,
    diagnose: bool = True,
) -> SequenceReport:
    """Solve every stage in order, writing problems, postures and ``sequence.json``.

    ``progress(k, n, stage_name, report)`` is called before (report None) and after each
    stage. A failed stage ends the sequence (its posture file is still written); with
    ``diagnose`` its report and posture file say what blocks it
    (:func:`posturegen.solver.diagnose.diagnose`)."""
    seq = F.require_mapping(seq, "sequence")
    F.check_keys(
        seq,
        "sequence",
        ["robot", "stages"],
        [*_SCENE_KEYS, "name", "description", "initial", "options"],
    )
    stages = seq["stages"]
    if not isinstance(stages, list) or not stages:
        raise InputError("stages", "expected a non-empty list", "add stages: [{name, contacts}]")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = SequenceReport(str(seq.get("name", "sequence")), planned=len(stages))
    previous: Problem | None = None
    q_prev: np.ndarray | None = None
    for k, stage in enumerate(stages):
        name = str(F.require_mapping(stage, f"stages[{k}]").get("name", f"stage {k}"))
        if progress:
            progress(k, len(stages), name, None)
        t0 = time.perf_counter()
        data = stage_problem_dict(seq, stage, k, previous, q_prev)
        problem = problem_from_dict(data)
        result = solve(problem)
        if diagnose:
            result = diagnosed(problem, result)
        wall = time.perf_counter() - t0
        stem = f"{k:02d}-{_slug(name)}"
        (out / f"{stem}.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        posture = dict(result.posture)
        posture["stage"] = {"index": k, "name": name, "sequence": report.name}
        write_posture(out / f"{stem}.json", posture)
        rep = StageReport(name, f"{stem}.yaml", f"{stem}.json", result, wall, result.diagnosis)
        report.stages.append(rep)
        if progress:
            progress(k, len(stages), name, rep)
        _write_index(seq, report, out)
        if not result.success and stop_on_failure:
            break
        previous, q_prev = problem, result.q
    return report


def _write_index(seq: dict[str, Any], report: SequenceReport, out: Path) -> None:
    robot = seq["robot"] if isinstance(seq["robot"], str) else seq["robot"].get("name", "custom")
    # stage posture paths as written (relative to out): write_sequence stores them relative
    stages = [{**s.to_dict(), "posture": str(out / s.posture_file)} for s in report.stages]
    write_sequence(
        out / "sequence.json",
        stages,
        name=report.name,
        description=seq.get("description", ""),
        robot=robot,
        success=report.success,
        planned_stages=report.planned,
    )
