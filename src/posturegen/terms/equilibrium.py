"""The static equilibrium (paper eq. 1, rows 5-6): zero resultant wrench on the robot, and the
actuated joints' torques within their limits."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .nlp import BuildContext, Instance, Term

TORQUE_LIMITS = "torque_limits"  # the block of |τ_j| / effort_j <= s rows


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
            nlp.constrain(TORQUE_LIMITS, scaled, -1.0, 1.0)  # scaled per instance: bounds()
        nlp.output("torques", tau)
        ctx.torques = tau

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {"equilibrium.reference_point": problem.q_init[0:3]}

    def bounds(self, problem: Instance) -> dict[str, tuple[float, float]]:
        if not np.any(np.isfinite(problem.robot.effort_limit)):
            return {}
        s = problem.torque_limit_scale
        return {TORQUE_LIMITS: (-s, s)}
