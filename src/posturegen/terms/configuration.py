"""The configuration term: the robot's variables (base position, base rotation, joints) and
the joint limits as their bounds."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from .nlp import BuildContext, Instance, Term, base_rotation

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

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
        return {"base.R0": R0}

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        q = problem.q_init
        lo, hi = problem.robot.q_lower, problem.robot.q_upper
        return {
            "base.position": q[0:3],
            "base.rotation": np.zeros(3),
            "joints": np.clip(q[7:], lo, hi),
        }
