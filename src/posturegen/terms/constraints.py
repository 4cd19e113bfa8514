"""Constraint terms of the posture problem: configuration and joint limits, static equilibrium
with torque limits, and frame tasks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..solver.problem import BuildContext, Problem, Term, base_rotation

# Bound on each component of the base rotation's exponential coordinates [rad]: keeps the
# local map far from its singularity at |w| = 2π and the series of so3_exp accurate.
BASE_ROTATION_BOUND = 2.5


class ConfigurationTerm(Term):
    """q = (base position, base rotation R0·exp([w]×), joints) with joint limits as bounds.

    Variables: ``base.position`` (3,) [m], ``base.rotation`` w (3,) [rad], ``joints`` (nj,)
    bounded by the URDF limits. Parameters: ``base.R0`` (9,), the initial base rotation.
    """

    name = "configuration"

    def key(self) -> tuple[Any, ...]:
        return ("configuration",)

    def declare(self, ctx: BuildContext) -> None:
        nlp, robot = ctx.nlp, ctx.robot
        p = nlp.variable("base.position", 3)
        w = nlp.variable("base.rotation", 3, -BASE_ROTATION_BOUND, BASE_ROTATION_BOUND)
        qj = nlp.variable("joints", robot.nj, robot.q_lower, robot.q_upper)
        R0 = ca.reshape(nlp.parameter("base.R0", 9), 3, 3)
        ctx.state = ctx.kin.forward(p, base_rotation(R0, w), qj)
        ctx.base_position, ctx.base_rotation, ctx.joints = p, w, qj

    def parameters(self, problem: Problem) -> dict[str, np.ndarray]:
        R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
        return {"base.R0": R0}

    def initial_guess(self, problem: Problem) -> dict[str, np.ndarray]:
        q = problem.q_init
        lo, hi = problem.robot.q_lower, problem.robot.q_upper
        return {
            "base.position": q[0:3],
            "base.rotation": np.zeros(3),
            "joints": np.clip(q[7:], lo, hi),
        }


class StaticEquilibrium(Term):
    """τ + Jᵀf = g(q): six base rows (zero resultant wrench, world frame, scaled by the weight)
    and |τ_j| <= s·effort_j for the actuated joints, τ = g_j(q) - (Jᵀf)_j, s the problem's
    ``torque_limit_scale`` (1 by default; < 1 keeps a safety margin)."""

    name = "equilibrium"

    def key(self) -> tuple[Any, ...]:
        return ("equilibrium",)

    def declare(self, ctx: BuildContext) -> None:
        nlp, robot = ctx.nlp, ctx.robot
        F, N, tau = ctx.kin.static_wrench_terms(ctx.state, ctx.force_points)
        p_ref = nlp.parameter("equilibrium.reference_point", 3)
        W = robot.weight
        nlp.constrain("equilibrium.force", F / W, 0.0, 0.0)
        # moment about a point near the robot, equivalent once the force rows hold
        nlp.constrain("equilibrium.moment", (N - ca.cross(p_ref, F)) / W, 0.0, 0.0)
        finite = np.flatnonzero(np.isfinite(robot.effort_limit))
        if finite.size:
            scaled = ca.vertcat(*[tau[i] / robot.effort_limit[i] for i in finite])
            nlp.constrain("torque_limits", scaled, -1.0, 1.0)  # scaled per instance: bounds()
        nlp.output("torques", tau)
        ctx.torques = tau

    def parameters(self, problem: Problem) -> dict[str, np.ndarray]:
        return {"equilibrium.reference_point": problem.q_init[0:3]}

    def bounds(self, problem: Problem) -> dict[str, tuple[float, float]]:
        if not np.any(np.isfinite(problem.robot.effort_limit)):
            return {}
        s = problem.torque_limit_scale
        return {"torque_limits": (-s, s)}


@dataclass
class PositionTask(Term):
    """Frame position = target (3,) [m] in world, optionally orientation = R_target.

    Hard constraint by default; with ``weight`` it becomes the cost
    weight·(|p - target|² / (0.1 m)² + |log(R_targetᵀ R)|²).
    """

    frame: str
    frame_id: int
    target: np.ndarray  # (3,) [m]
    R_target: np.ndarray | None = None  # (3, 3) or None
    weight: float | None = None
    index: int = 0

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"task{self.index}.{self.frame}"

    def key(self) -> tuple[Any, ...]:
        return ("position", self.frame_id, self.R_target is not None, self.weight is not None)

    def declare(self, ctx: BuildContext) -> None:
        nlp = ctx.nlp
        R, p = ctx.kin.frame_placement(ctx.state, self.frame_id)
        target = nlp.parameter(f"{self.name}.target", 3)
        err = p - target
        rot_err = None
        if self.R_target is not None:
            Rt = ca.reshape(nlp.parameter(f"{self.name}.R_target", 9), 3, 3)
            E = Rt.T @ R
            rot_err = 0.5 * ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])
        if self.weight is None:
            nlp.constrain(f"{self.name}.position", err, 0.0, 0.0)
            if rot_err is not None:
                nlp.constrain(f"{self.name}.orientation", rot_err, 0.0, 0.0)
                # the skew part vanishes for 0 and π: keep the trace positive (same branch)
                nlp.constrain(f"{self.name}.orientation_branch", ca.trace(E), 0.0, np.inf)
        else:
            cost = ca.sumsqr(err) / 0.01
            if rot_err is not None:
                cost += ca.sumsqr(rot_err)
            nlp.minimize(self.name, self.weight * cost)
        nlp.output(f"{self.name}.position", p)
        nlp.output(f"{self.name}.rotation", R)

    def parameters(self, problem: Problem) -> dict[str, np.ndarray]:
        out = {f"{self.name}.target": self.target}
        if self.R_target is not None:
            out[f"{self.name}.R_target"] = self.R_target
        return out
