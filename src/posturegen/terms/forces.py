"""Contact forces: f = W·R_s·φ at a contact's points, φ in the surface frame (φ_n >= 0), the
friction model on each φ, and their entries in the posture file.

A contact with a *grip* G [N] (a hand closed around a rail or a rung) presses on its surface
with G/k at each of its k points beyond what the posture's load asks: its force points bear
φ = ψ - γ·n with ψ_n >= 0 and the friction model on ψ, γ = G/(k·W) (the friction cone's apex
moved G/k below the surface: a point may pull by up to G/k, and its friction grows with the
grip). The grip is internal to the hand: only φ enters the equilibrium."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .friction import FrictionModel
from .nlp import BuildContext, Instance


def declare_forces(
    ctx: BuildContext,
    pre: str,
    joint_id: int,
    points_world: list[ca.SX],
    friction: FrictionModel,
    Rs: ca.SX,
    grip: bool = False,
) -> ca.SX:
    """Force variables at world points attached to joint ``joint_id``: f = W·R_s·φ with φ in
    the surface frame (φ_n >= 0), W the robot's weight, and the friction model on each φ; with
    ``grip``, φ = ψ - γ·n (the module's doc), ψ the variables, γ the parameter ``{pre}.grip``.

    Declares ``{pre}.forces`` (3k,) and the parameter ``{pre}.mu``; ``Rs`` is R_world_surface; adds
    the forces to the equilibrium and the outputs ``{pre}.points`` and ``{pre}.forces``; returns
    the normal components of the variables, ψ_n (k,) (φ_n without a grip)."""
    nlp, k = ctx.nlp, len(points_world)
    phi = nlp.variable(f"{pre}.forces", 3 * k, np.tile([-np.inf, -np.inf, 0.0], k), np.inf)
    mu = nlp.parameter(f"{pre}.mu", 1)
    pull = ca.vertcat(0, 0, nlp.parameter(f"{pre}.grip", 1)) if grip else None
    W = ctx.robot.weight
    fric, f_world = [], []
    for i, pw in enumerate(points_world):
        phi_i = phi[3 * i : 3 * i + 3]
        fric.append(friction.constraints(phi_i, mu))
        fw = W * (Rs @ (phi_i if pull is None else phi_i - pull))
        ctx.force_points.append((joint_id, pw, fw))
        f_world.append(fw)
    nlp.constrain(f"{pre}.friction", ca.vertcat(*fric), -np.inf, 0.0)
    nlp.output(f"{pre}.points", ca.horzcat(*points_world))
    nlp.output(f"{pre}.forces", ca.horzcat(*f_world))
    return phi[2::3]


def grip_parameter(grip: float, weight: float, n_points: int) -> np.ndarray:
    """γ (1,): a grip of ``grip`` [N] shared by ``n_points`` points, over the weight [N]."""
    return np.array([grip / (weight * n_points)])


def force_guess(problem: Instance, n_points: int) -> np.ndarray:
    """Initial φ (3·n_points,): the weight shared evenly over every force point, along the
    normal."""
    total = sum(c.force_points_count() for c in problem.contacts) or 1
    return np.tile([0.0, 0.0, 1.0 / total], n_points)


def forces_dict(frame: str, outputs: dict[str, np.ndarray], pre: str) -> list[dict[str, Any]]:
    """The posture file's forces of a contact: ``{frame, point, force}`` per force point."""
    pts = outputs[f"{pre}.points"].reshape(3, -1, order="F").T
    fs = outputs[f"{pre}.forces"].reshape(3, -1, order="F").T
    return [
        {"frame": frame, "point": p.tolist(), "force": f.tolist()}
        for p, f in zip(pts, fs, strict=True)
    ]
