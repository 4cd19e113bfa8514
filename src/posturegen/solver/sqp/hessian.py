"""Making the Hessian of the Lagrangian positive definite for the SQP's QP.

The posture program's Lagrangian is indefinite where the constraints bend against their
multipliers (sphere pairs sliding on each other, the equilibrium's bilinear q·f terms) and
singular along the contact forces (they enter linearly). In the variables scaled by the
trust region's units (radians, metres, newtons / robot weight), B̃ = V max(Λ, δ) Vᵀ: the
eigenvalues below δ are raised to δ, the others and every direction kept (not the whole
matrix shifted). Clipping against flipping (|Λ|), talos-reach-balance-collision, 20
problems: 32.5 against 38.1 ms median, p90 39.8 against 74.6 ms; δ = 1e-4 against 1e-3 or
1e-5: 11 median iterations each, 1e-5 ran one problem into 149 s of QPs. A positive definite
semi-definite Hessian is only lifted by δ and skips the decomposition (one Cholesky
factorization tells)."""

from __future__ import annotations

import numpy as np

DELTA = 1e-4  # the smallest eigenvalue in scaled variables
# the largest: where the multipliers run away (an unload of HRP-2's vertical ladder whose
# elastic QPs drove them towards the penalty's 1e8), B̃'s largest eigenvalue reached 4.7e10,
# daqp's factorization called it not convex and proxsuite, its fallback, took seconds a QP
# (146 s for one posture; 1.9 s capped). On the never-seen families max |B̃| is 1.6e4 at
# most iterates; a cap of 1e6 changed the path of one of 40 stances (the same verified), 1e8
# none of the four families'
CURVATURE_MAX = 1e8


def convexified(H: np.ndarray, scale: np.ndarray, delta: float = DELTA) -> tuple[np.ndarray, bool]:
    """(B̃, modified): the Hessian in the scaled variables d̃ = d / s made positive definite,
    B̃ = S H S + δ I when S H S + δ/2 I is positive definite (S = diag(scale): where S H S is
    positive semi-definite, its smallest eigenvalue lifted to δ), else V clip(Λ, δ,
    CURVATURE_MAX) Vᵀ with S H S = V Λ Vᵀ (also when an entry of S H S exceeds the cap).
    B̃'s eigenvalues are at least δ/2: the QP is solved in these variables (in metres and
    newtons, the forces' δ / weight² made a Talos QP's condition number 6e12)."""
    Hs = H * np.outer(scale, scale)
    # δ on the diagonal alone where the curvature is only missing (the forces enter
    # linearly: their block is zero), not negative
    lifted = Hs + delta * np.eye(H.shape[0])
    if np.abs(lifted).max() <= CURVATURE_MAX:
        try:
            np.linalg.cholesky(lifted - 0.5 * delta * np.eye(H.shape[0]))
            return lifted, False
        except np.linalg.LinAlgError:
            pass
    w, V = np.linalg.eigh(Hs)
    return (V * np.clip(w, delta, CURVATURE_MAX)) @ V.T, True
