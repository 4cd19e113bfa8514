"""The elastic QP of the Sℓ1QP step: when a QP's linearized rows cannot all hold (inside the
trust region, or at all), each row gets slacks priced at the penalty ν,

    minimize ½ dᵀBd + cᵀd + ν Σ (s⁺ + s⁻) + ½ ε Σ (s⁺² + s⁻²)
    subject to  lbA <= A d + s⁺ - s⁻ <= ubA,  s⁺, s⁻ >= 0,  lb <= d <= ub,

whose solution minimizes the ℓ1 model of the merit function f + ν‖viol(g)‖₁ in the region.
Its row multipliers are bounded by ν (a slack's price), so they cannot drive the penalty up.
Only the slacks a row can use are added: s⁺ where lbA is finite, s⁻ where ubA is."""

from __future__ import annotations

import numpy as np

from ..qp import registry
from ..qp.base import QP, QPSolution
from .hessian import DELTA

EPSILON = 1e-8  # the slacks' quadratic weight relative to ν (B must be positive definite)
# ... and at least the smallest curvature of the variables' block (the QP is in the scaled
# variables, whose B's eigenvalues are at least δ/2): with 1e-8 ν alone, daqp found the
# elastic QPs of Talos' unloads not convex (its Cholesky factorization failed) and proxsuite,
# its fallback, ran its 1000 iterations for 11 s a QP
SLACK_CURVATURE_MIN = 0.5 * DELTA


def solve_elastic(qp: QP, penalty: float, backend: str | None = None) -> QPSolution:
    """The elastic QP of ``qp`` at penalty ν; returns d and its multipliers (the slacks'
    own dropped), the rows' as the elastic QP gives them."""
    n, m = qp.c.size, qp.lbA.size
    up = np.flatnonzero(np.isfinite(qp.lbA))  # rows that may need s⁺ (raise A d)
    down = np.flatnonzero(np.isfinite(qp.ubA))  # rows that may need s⁻ (lower A d)
    k = up.size + down.size
    A = np.zeros((m, n + k))
    A[:, :n] = qp.A
    A[up, n + np.arange(up.size)] = 1.0
    A[down, n + up.size + np.arange(down.size)] = -1.0
    B = np.zeros((n + k, n + k))
    B[:n, :n] = qp.B
    B[n:, n:] = np.eye(k) * max(EPSILON * penalty, SLACK_CURVATURE_MIN)
    c = np.concatenate([qp.c, np.full(k, penalty)])
    elastic = QP(
        B=B,
        c=c,
        A=A,
        lb=np.concatenate([qp.lb, np.zeros(k)]),
        ub=np.concatenate([qp.ub, np.full(k, np.inf)]),
        lbA=qp.lbA,
        ubA=qp.ubA,
        equal=qp.equal,
    )
    sol = registry.solve(elastic, backend)
    return QPSolution(sol.status, sol.d[:n], sol.lam_bounds[:n], sol.lam_rows, sol.iterations)
