"""Elastic programs: the hard rows of a posture program relaxed by slacks (for the diagnosis).

A row ``lb <= g(x) <= ub`` of a softened block becomes ``lb <= g(x) + s⁺ - s⁻ <= ub`` with
``s⁺, s⁻ >= 0`` (the variables ``slack.BLOCK``, 2·rows), and the cost becomes
``Σ_b w_b·Σ(s⁺ + s⁻) + cost_scale·f(x)``: an exact L1 penalty, so a slack is positive only where
no posture meets its row (up to the weights' trade-offs). Which blocks are softened is decided
by their name's category (:func:`category`): tasks, torque limits, contact rows, friction and
collision rows; the static equilibrium, joint limits and force bounds stay hard.

The weights say which rows the diagnosis blames when several could move: 1 cm of a target or
of a proxy distance costs as much as 10 % of a torque limit or 10 % of the robot's weight
outside a friction cone (the robot's limits are what a posture beyond them needs, and a target
is beyond reach only where more torque would not reach it), a contact's placement three times
more (a target out of reach is reported as such rather than as both feet moving towards it).
Weights are per unit of the row: torque rows are τ/effort, friction rows are forces over the
robot's weight, the others metres (orientations: sines of angles).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .equilibrium import TORQUE_LIMITS

SLACK_PREFIX = "slack."


@dataclass(frozen=True)
class Elastic:
    """Which block categories get slacks, their L1 weights, and the factor on the original
    cost (it still regularizes the program, far below the penalty)."""

    weights: tuple[tuple[str, float], ...] = (
        ("torque", 10.0),  # per 100 % of a torque limit: 1 % costs 0.1
        ("friction", 10.0),  # per robot weight of force outside a cone: 1 % costs 0.1
        ("collision", 100.0),  # per m of proxy distance below the margin: 1 cm costs 1
        ("task", 100.0),  # per m (and per unit of sin(angle)) of a target: 1 cm costs 1
        ("contact", 300.0),  # per m (and sin(angle)) of a contact's placement: 1 cm costs 3
    )
    cost_scale: float = 1e-2

    def weight(self, block: str) -> float | None:
        """The L1 weight of a constraint block's slacks, None when the block stays hard."""
        return dict(self.weights).get(category(block) or "")


def category(block: str) -> str | None:
    """The category of a constraint block from its name (None: a block that stays hard)."""
    if block == TORQUE_LIMITS:
        return "torque"
    if block.startswith("task"):
        return "task"
    if block.startswith("collision."):
        return "collision"
    if block.startswith("contact."):
        return "friction" if block.endswith(".friction") else "contact"
    return None


def soften(nlp: Any, elastic: Elastic) -> None:
    """Add slacks to the softened blocks of a declared :class:`posturegen.solver.problem.NLP` (in
    place): each row gets ``+ s⁺ - s⁻``, the cost the L1 penalty and the scaled original."""
    penalty = ca.SX(0)
    for name, (expr, lb, ub) in list(nlp.g.items()):
        w = elastic.weight(name)
        if w is None:
            continue
        n = expr.shape[0]
        s = nlp.variable(SLACK_PREFIX + name, 2 * n, 0.0, np.inf)
        nlp.g[name] = (expr + s[:n] - s[n:], lb, ub)
        if name in nlp.derivatives:
            nlp.derivatives[name] = _with_slacks(nlp.derivatives[name], s, n)
        penalty = penalty + w * ca.sum1(s)
    for name in list(nlp.costs):
        nlp.costs[name] = elastic.cost_scale * nlp.costs[name]
    nlp.minimize("elastic", penalty)


def _with_slacks(given: Any, s: ca.SX, n: int) -> Callable[[], Any]:
    """A block's hand-built derivatives (a BlockDerivatives, or the function that builds them)
    extended to its slacks: z' = (z, s⁺, s⁻), ∂g/∂z' = [J, I, -I], the Hessian zero in s."""

    def build() -> Any:
        d = given() if callable(given) else given
        eye = ca.SX.eye(n)
        nz = d.z.shape[0]
        return dataclasses.replace(
            d,
            z=ca.vertcat(d.z, s),
            jacobian=ca.horzcat(d.jacobian, eye, -eye),
            hessian=ca.diagcat(d.hessian, ca.SX(2 * n, 2 * n)) if nz else ca.SX(2 * n, 2 * n),
        )

    return build


def slack_values(x: np.ndarray, x_index: dict[str, slice]) -> dict[str, np.ndarray]:
    """The net slack s⁺ - s⁻ (rows,) of every softened block in a solution x: the amount by
    which its row had to move (g(x) + slack meets the bounds)."""
    out = {}
    for name, sl in x_index.items():
        if name.startswith(SLACK_PREFIX):
            s = x[sl]
            n = s.size // 2
            out[name[len(SLACK_PREFIX) :]] = s[:n] - s[n:]
    return out
