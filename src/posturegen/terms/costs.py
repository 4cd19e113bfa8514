"""Cost terms: distance to the initial posture, force and torque regularization."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .nlp import BuildContext, Instance, Term


@dataclass
class PostureCost(Term):
    """weight·(|qj - qj0|² + |p - p0|²/(0.1 m)² + |w|²): stay close to the initial posture.

    ``reference`` chooses qj0: ``initial`` (the problem's initial posture) or ``default`` (the
    robot's default posture, e.g. half-sitting: what a climb's stages keep coming back to,
    while each stage still starts from the previous posture), put at least
    :data:`REFERENCE_INSET` inside the joint limits (:func:`reference_inside_limits`)."""

    weight: float = 1.0
    reference: str = "initial"
    name: str = "posture"

    def key(self) -> tuple[Any, ...]:
        return ("posture",)

    def declare(self, ctx: BuildContext) -> None:
        nlp = ctx.nlp
        qj0 = nlp.parameter("posture.joints0", ctx.robot.nj)
        p0 = nlp.parameter("posture.base0", 3)
        w = nlp.x["base.rotation"][0]
        weight = nlp.parameter("posture.weight", 1)
        nlp.minimize(
            self.name,
            weight
            * (
                ca.sumsqr(ctx.joints - qj0)
                + ca.sumsqr(ctx.base_position - p0) / 0.01
                + ca.sumsqr(w)
            ),
        )

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        robot = problem.robot
        qj0 = robot.q_init[7:] if self.reference == "default" else problem.q_init[7:]
        return {
            "posture.joints0": reference_inside_limits(qj0, robot.q_lower, robot.q_upper),
            "posture.base0": problem.q_init[0:3],
            "posture.weight": np.array([self.weight]),
        }


# [rad or m] how far inside its limits a joint's posture reference is put. A reference on a
# limit (Talos' grippers at 0 = their upper limit) makes the optimum a degenerate active
# bound (zero multiplier): IPOPT then converges linearly, the step halving each iteration
# (talos-near-body-free 18 -> 14 median iterations, talos-stand-reach 16 -> 12 with the inset).
REFERENCE_INSET = 0.01


def reference_inside_limits(qj0: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """qj0 (nj,) clipped to [lower + δ, upper - δ], δ = min(REFERENCE_INSET, range/4)."""
    inset = np.minimum(REFERENCE_INSET, 0.25 * np.where(upper > lower, upper - lower, 0.0))
    return np.clip(qj0, lower + inset, upper - inset)


@dataclass
class ForceCost(Term):
    """weight·Σ|f_i|²/W²: spreads the load over the contact points (W the robot's weight)."""

    weight: float = 1e-2
    name: str = "forces"

    def key(self) -> tuple[Any, ...]:
        return ("forces",)

    def declare(self, ctx: BuildContext) -> None:
        W = ctx.robot.weight
        weight = ctx.nlp.parameter("forces.weight", 1)
        total = sum((ca.sumsqr(f) for _, _, f in ctx.force_points), ca.SX(0))
        ctx.nlp.minimize(self.name, weight * total / W**2)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {"forces.weight": np.array([self.weight])}


@dataclass
class TorqueCost(Term):
    """weight·Σ(τ_j/effort_j)²: prefers postures far from the torque limits."""

    weight: float = 1e-2
    name: str = "torques"

    def key(self) -> tuple[Any, ...]:
        return ("torques",)

    def declare(self, ctx: BuildContext) -> None:
        effort = ctx.robot.effort_limit
        scale = np.where(np.isfinite(effort), effort, 100.0)
        weight = ctx.nlp.parameter("torques.weight", 1)
        tau = ctx.torques
        ctx.nlp.minimize(self.name, weight * ca.sumsqr(tau / ca.DM(scale)))

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {"torques.weight": np.array([self.weight])}
