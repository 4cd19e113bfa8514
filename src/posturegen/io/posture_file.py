"""The posture file (JSON, ``"schema": "posturegen.posture/1"``): its schema, its one writer
(:func:`posture_dict`, :func:`write_posture`) and its one reader (:func:`load_posture`,
:func:`check_posture`). Everything that reads or writes a posture file goes through here: the
solve, ``posturegen verify``, the figures and the viewer."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..checks import VerifyReport
from ..collision.boxes import env_boxes, excluded_joint_ids
from ..collision.pairs import pair_rule, unchecked_entries
from ..errors import InputError
from ..solver.problem import Problem, Program

SCHEMA = "posturegen.posture/1"
# the keys every posture file has (the solver's fields aside)
REQUIRED = ("robot", "q", "torques", "contacts")


def write_posture(path: str | Path, posture: dict[str, Any]) -> Path:
    """Write a posture dict to ``path`` (JSON; folders made as needed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(posture, indent=1))
    return path


def check_posture(data: Any, where: str, fix: str) -> dict[str, Any]:
    """``data`` when it is a posture dict (schema and :data:`REQUIRED` keys), else an
    InputError naming ``where`` and the missing field, with ``fix``."""
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        raise InputError(f"{where}: schema", f'expected "{SCHEMA}"', fix)
    for key in REQUIRED:
        if key not in data:
            raise InputError(f"{where}: {key}", "missing", fix)
    return data


def read_json(path: str | Path, missing_fix: str, invalid_fix: str) -> Any:
    """The parsed JSON of a file, or an InputError naming the file (``missing_fix`` when it
    does not exist, ``invalid_fix`` when it is not JSON)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise InputError(str(path), "no such file", missing_fix) from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(str(path), "cannot read it", "check the path") from exc
    except json.JSONDecodeError as exc:
        raise InputError(str(path), f"invalid JSON at line {exc.lineno}", invalid_fix) from exc


def load_posture(path: str | Path) -> dict[str, Any]:
    """Read a posture file and check its schema and required fields."""
    path = Path(path)
    data = read_json(path, "give the path of a posture.json", "give a posture file")
    return check_posture(data, str(path), "give a file written by posturegen solve")


def load_posture_any(posture: str | Path | dict[str, Any]) -> dict[str, Any]:
    """A posture dict from a posture file path or a dict (both checked alike)."""
    if isinstance(posture, dict):
        return check_posture(posture, "posture", "give a posture written by solve")
    return load_posture(posture)


def model_of_posture(posture: dict[str, Any]) -> pin.Model:
    """The Pinocchio model named by a posture's ``robot`` entry (URDF + free flyer)."""
    urdf = Path(str(posture["robot"].get("urdf", "")))
    if not urdf.is_file():
        raise InputError("robot.urdf", f"no file {urdf}", "regenerate the posture on this machine")
    return pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())


def posture_dict(
    problem: Problem | Program,
    q: np.ndarray,
    torques: np.ndarray,
    outputs: dict[str, np.ndarray],
    margin: float | None = None,
) -> dict[str, Any]:
    """The posture-file content (schema posturegen.posture/1) without the solver fields (the
    solve adds them: see posturegen.solver.solve)."""
    robot = problem.robot
    return {
        "schema": SCHEMA,
        "robot": robot.to_dict(),
        "q": q.tolist(),
        "joint_names": robot.joint_names,
        "torques": np.asarray(torques).tolist(),
        "gravity": np.array(robot.model.gravity.linear).tolist(),
        "contacts": [c.to_dict(outputs) for c in problem.contacts],
        "tasks": [t.to_dict() for t in problem.tasks],
        "obstacles": [o.to_dict() for o in problem.scene.obstacles],
        "surfaces": [s.to_dict() for s in problem.scene.surfaces.values()],
        "self_collision": problem.self_collision,
        "torque_limit_scale": problem.torque_limit_scale,
        "collision": _collision_dict(problem, margin),
    }


def add_solve_fields(
    posture: dict[str, Any],
    success: bool,
    status: str,
    message: str,
    iterations: int,
    solve_time_s: float,
    ipopt_runs: int,
    report: VerifyReport,
) -> None:
    """The solver's fields of a posture file, added to ``posture``."""
    posture.update(
        {
            "success": success,
            "status": status,
            "message": message,
            "iterations": iterations,
            "solve_time_s": solve_time_s,
            "ipopt_runs": ipopt_runs,
            "max_violation": report.max_violation,
            "diagnosis": None,
            "checks": {
                c.name: {"value": c.value, "tolerance": c.tolerance, "ok": c.ok, "detail": c.detail}
                for c in report.checks
            },
            "notes": list(report.notes),
        }
    )


def _collision_dict(problem: Problem | Program, margin: float | None) -> dict[str, Any] | None:
    """What the mesh check must test: the boxes, and the pairs it leaves unchecked with the
    reason of each (posturegen.collision.pairs; verify recomputes all but the user's)."""
    opts = problem.collision_options
    if opts is None:
        return None
    robot = problem.robot
    model = robot.model
    unchecked: list[dict[str, Any]] = []
    if opts.self_collision:
        geometry = robot.collision_model()
        rule = pair_rule(model, geometry, str(robot.srdf) if robot.srdf else None)
        user = frozenset(excluded_joint_ids(robot, opts))
        unchecked = unchecked_entries(model, geometry, rule, user)
    return {
        "margin": opts.margin if margin is None else margin,
        "self": opts.self_collision,
        "unchecked": unchecked,
        "boxes": [b.to_dict(model) for b in env_boxes(problem)],
    }
