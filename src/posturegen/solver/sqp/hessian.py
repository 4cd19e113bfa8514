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


# the weights τ tried along the rows and bounds that hold, each × max(1, max |S H S|):
# B̃ = S H S + δ I + τ Âᵀ Â (Â: their gradients in the scaled variables, each of norm 1). On
# their null space B̃ is S H S + δ I: while they hold, the QP's step is Newton's wherever ∇²L
# is positive there (clipped eigenvalues bent it, and the runs converged linearly: a reach's
# last 20 iterations each did 61 % of what its model promised, its ∇²L negative along a
# direction that a row held)
AUGMENT = (1e-4, 1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0)


def _positive(B: np.ndarray, delta: float) -> bool:
    """Whether B - δ/2 I is positive definite, B's entries within CURVATURE_MAX."""
    if np.abs(B).max() > CURVATURE_MAX:
        return False
    try:
        np.linalg.cholesky(B - 0.5 * delta * np.eye(B.shape[0]))
    except np.linalg.LinAlgError:
        return False
    return True


def convexified(
    H: np.ndarray, scale: np.ndarray, held: np.ndarray, delta: float = DELTA
) -> tuple[np.ndarray, bool, np.ndarray]:
    """(B̃, modified, gain): the Hessian in the scaled variables d̃ = d / s made positive
    definite. B̃ = S H S + δ I when that is (S = diag(scale): where S H S is positive
    semi-definite, its smallest eigenvalue lifted to δ); else S H S + δ I + τ Âᵀ Â for the
    first τ of AUGMENT that makes it so (Â: ``held`` (k, n), the gradients of the rows and
    bounds that hold in the scaled variables, normalized); a QP's multiplier of held row i
    is then off by gain_i (held_i · d̃) where it holds, gain_i = τ / ‖held_i‖² (k,); else
    V clip(Λ, δ, CURVATURE_MAX) Vᵀ with S H S = V Λ Vᵀ. B̃'s eigenvalues are at least δ/2:
    the QP is solved in these variables (in metres and newtons, the forces' δ / weight² made
    a Talos QP's condition number 6e12)."""
    Hs = H * np.outer(scale, scale)
    gain = np.zeros(len(held))
    # δ on the diagonal alone where the curvature is only missing (the forces enter
    # linearly: their block is zero), not negative
    lifted = Hs + delta * np.eye(H.shape[0])
    if _positive(lifted, delta):
        return lifted, False, gain
    norms = np.linalg.norm(held, axis=1)
    rows = norms > 0
    if rows.any():
        unit = held[rows] / norms[rows, None]
        G = unit.T @ unit
        base = max(1.0, float(np.abs(Hs).max()))
        for weight in AUGMENT:
            B = lifted + (weight * base) * G
            if _positive(B, delta):
                gain[rows] = weight * base / norms[rows] ** 2
                return B, True, gain
    w, V = np.linalg.eigh(Hs)
    return (V * np.clip(w, delta, CURVATURE_MAX)) @ V.T, True, gain
