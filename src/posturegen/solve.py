"""Solving a :class:`~posturegen.problem.Problem`: IPOPT, then an independent re-check.

``solve`` returns a frozen :class:`Result`. ``success`` is True only when IPOPT converged AND
:func:`posturegen.verify.verify_posture` (Pinocchio, not CasADi) accepts the posture.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .problem import Problem
from .verify import SCHEMA, VerifyReport, verify_posture

_IPOPT_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass(frozen=True)
class ContactForce:
    """A force on the robot [N] at a world point [m], applied to a point of ``frame``."""

    frame: str
    point: np.ndarray  # (3,) world [m]
    force: np.ndarray  # (3,) world [N]


@dataclass(frozen=True)
class Result:
    """A solved posture. ``success`` means IPOPT converged and the re-check passed."""

    success: bool
    status: str  # IPOPT's return status
    message: str  # why it failed, or "verified"
    iterations: int
    solve_time_s: float  # IPOPT's own wall time [s]
    build_time_s: float  # time to build the solver (0 when it came from the cache) [s]
    q: np.ndarray  # (nq,) Pinocchio order: base xyz, quaternion xyzw, joints
    torques: np.ndarray  # (nj,) actuated joints, velocity order [N·m]
    forces: dict[str, tuple[ContactForce, ...]]  # per contact name
    cost: float
    verification: VerifyReport
    posture: dict[str, Any]  # the posture-file content

    @property
    def max_violation(self) -> float:
        """Worst value among the re-check's quantities (see :class:`VerifyReport`)."""
        return self.verification.max_violation

    def write(self, path: str | Path) -> Path:
        """Write the posture file (JSON)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.posture, indent=1))
        return path


def solve(problem: Problem, x0: np.ndarray | None = None) -> Result:
    """Solve the posture problem and verify the posture; never raises for 'not found'."""
    built_before = problem.key() in _cache_keys()
    compiled = problem.compile()
    x_init, p, lbg, ubg = problem.numeric(compiled)
    if x0 is not None:
        x_init = np.asarray(x0, dtype=float)
    t0 = time.perf_counter()
    sol = compiled.solver(x0=x_init, p=p, lbx=compiled.lbx, ubx=compiled.ubx, lbg=lbg, ubg=ubg)
    wall = time.perf_counter() - t0
    stats = compiled.solver.stats()
    status = str(stats.get("return_status", "unknown"))
    solve_time = float(stats.get("t_wall_total", wall))
    x = np.array(sol["x"]).ravel()
    out = compiled.outputs(x=x, p=p)
    outputs = {k: np.array(v).ravel(order="F") for k, v in out.items()}
    q = configuration_from_x(problem, compiled, x)
    torques = outputs["torques"]
    posture = posture_dict(problem, q, torques, outputs)
    report = verify_posture(posture, problem.robot.model)
    ipopt_ok = status in _IPOPT_OK
    success = ipopt_ok and report.ok
    if success:
        message = "verified"
    elif not ipopt_ok:
        message = f"IPOPT did not converge ({status})"
    else:
        message = "IPOPT converged but the re-check failed: " + "; ".join(
            f"{c.name} {c.value:.3g} > {c.tolerance:.1g}" for c in report.failures
        )
    posture.update(
        {
            "success": success,
            "status": status,
            "message": message,
            "iterations": int(stats.get("iter_count", -1)),
            "solve_time_s": solve_time,
            "max_violation": report.max_violation,
            "checks": {
                c.name: {"value": c.value, "tolerance": c.tolerance, "ok": c.ok}
                for c in report.checks
            },
        }
    )
    forces = {
        c["name"]: tuple(
            ContactForce(f["frame"], np.array(f["point"]), np.array(f["force"]))
            for f in c["forces"]
        )
        for c in posture["contacts"]
    }
    return Result(
        success=success,
        status=status,
        message=message,
        iterations=int(stats.get("iter_count", -1)),
        solve_time_s=solve_time,
        build_time_s=0.0 if built_before else compiled.build_time_s,
        q=q,
        torques=torques,
        forces=forces,
        cost=float(sol["f"]),
        verification=report,
        posture=posture,
    )


def _cache_keys() -> set[Any]:
    from .problem import _CACHE

    return set(_CACHE)


def configuration_from_x(problem: Problem, compiled: Any, x: np.ndarray) -> np.ndarray:
    """Pinocchio q (nq,) from the solver's variables: R = R0·exp(w) computed exactly."""
    p = x[compiled.x_index["base.position"]]
    w = x[compiled.x_index["base.rotation"]]
    qj = x[compiled.x_index["joints"]]
    R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
    quat = pin.Quaternion(R0 @ pin.exp3(w)).normalized().coeffs()  # (x, y, z, w)
    return np.concatenate([p, quat, qj])


def posture_dict(
    problem: Problem, q: np.ndarray, torques: np.ndarray, outputs: dict[str, np.ndarray]
) -> dict[str, Any]:
    """The posture-file content (schema posturegen.posture/1) without the solver fields."""
    robot = problem.robot
    tasks = []
    for t in problem.tasks:
        tasks.append(
            {
                "type": "position",
                "frame": t.frame,
                "target": np.asarray(t.target).tolist(),
                "rotation": None if t.R_target is None else np.asarray(t.R_target).tolist(),
                "weight": t.weight,
            }
        )
    return {
        "schema": SCHEMA,
        "robot": robot.to_dict(),
        "q": q.tolist(),
        "joint_names": robot.joint_names,
        "torques": np.asarray(torques).tolist(),
        "gravity": np.array(robot.model.gravity.linear).tolist(),
        "contacts": [c.to_dict(outputs) for c in problem.contacts],
        "tasks": tasks,
        "obstacles": [o.to_dict() for o in problem.scene.obstacles],
        "self_collision": problem.self_collision,
        "torque_limit_scale": problem.torque_limit_scale,
    }
