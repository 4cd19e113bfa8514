"""Making the Hessian of the Lagrangian positive definite for the SQP's QP.

The posture program's Lagrangian is indefinite where the constraints bend against their
multipliers (sphere pairs sliding on each other, the equilibrium's bilinear q·f terms) and
singular along the contact forces (they enter linearly). In the variables scaled by the
trust region's units (radians, metres, newtons / robot weight) it is made so first along the
rows and bounds that hold, keeping its curvature on their null space (see
:func:`convexified`); where that cannot be, B̃ = V max(|Λ|, δ) Vᵀ: every direction kept, a
negative eigenvalue flipped (its magnitude the step's scale), those below δ raised to δ.
When this was the only modification, clipping (max(Λ, δ)) beat flipping on 20 reach
problems (32.5 against 38.1 ms median); as the last resort, on 4 families x 2 seeds x 49
problems, flipping verified 385 -> 388 (the stances 91 -> 94): at a feasible point whose
reduced Hessian had a negative eigenvalue, clipping gave it δ and the steps crawled (a
near-body reach, 80 iterations of 1e-4). δ = 1e-4 against 1e-3 or 1e-5: 11 median
iterations each, 1e-5 ran one problem into 149 s of QPs. A positive semi-definite Hessian
is only lifted by δ and skips the decomposition (one Cholesky factorization tells)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

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
    """Whether B - δ/2 I is positive definite, B's entries within CURVATURE_MAX (LAPACK's
    Cholesky factorization succeeds: 10 µs on Talos' 62 variables, numpy's 19 µs, and the
    SQP makes 4-5 a step)."""
    if np.abs(B).max() > CURVATURE_MAX:
        return False
    return _factorizes(B, -0.5 * delta)


def _factorizes(B: np.ndarray, shift: float) -> bool:
    """Whether B + shift I (symmetric) has a Cholesky factorization (is positive definite)."""
    M = np.array(B, dtype=float, order="F")
    M.flat[:: M.shape[0] + 1] += shift
    _, info = lapack.dpotrf(M, lower=1, clean=0, overwrite_a=1)
    return info == 0


def convexified(
    H: np.ndarray, scale: np.ndarray, held: np.ndarray, delta: float = DELTA
) -> tuple[np.ndarray, bool, np.ndarray]:
    """(B̃, modified, C): the Hessian in the scaled variables d̃ = d / s made positive
    definite, and C (k, n) with (B̃ - S H S - δ I) d̃ = heldᵀ (C d̃) where that has a solution:
    a QP's multipliers of the ``held`` gradients (k, n) (the rows and bounds that hold, in
    the scaled variables) become those of S H S + δ I by adding C d̃. In order:

    - S H S + δ I when that is positive definite (S = diag(scale): where S H S is positive
      semi-definite, its smallest eigenvalue lifted to δ); C = 0;
    - S H S + δ I + τ ÂᵀÂ for the first τ of AUGMENT (× max(1, max |S H S|)) that makes it
      so, Â the held gradients normalized: the same on their null space; C = τ Â / ‖held‖;
    - where S H S + δ I is positive definite on the held gradients' null space (its
      eigenvalues there >= δ): Z Zᵀ (S H S + δ I) Z Zᵀ + Y clip(Yᵀ (S H S + δ I) Y) Yᵀ (Y, Z
      orthonormal bases of the held gradients' span and null space; clip: eigenvalues
      within [δ, CURVATURE_MAX]), its coupling with the span dropped (HRP-2 on a ladder:
      ∇²L positive on the null space of 71 held rows, but only τ ≈ 1e8 made the sum
      positive, a condition number of 1e11; clipped instead, its SQP crawled 400
      iterations at 1e-4 a step); C by least squares;
    - V clip(|Λ|, δ, CURVATURE_MAX) Vᵀ with S H S = V Λ Vᵀ; C = 0.

    B̃'s eigenvalues are at least δ/2: the QP is solved in these variables (in metres and
    newtons, the forces' δ / weight² made a Talos QP's condition number 6e12)."""
    Hs = H * np.outer(scale, scale)
    n = H.shape[0]
    none = np.zeros((len(held), n))
    # δ on the diagonal alone where the curvature is only missing (the forces enter
    # linearly: their block is zero), not negative
    lifted = Hs.copy()
    lifted.flat[:: n + 1] += delta
    if _positive(lifted, delta):
        return lifted, False, none
    norms = np.linalg.norm(held, axis=1)
    rows = norms > 0
    if rows.any():
        unit = held[rows] / norms[rows, None]
        G = unit.T @ unit
        base = max(1.0, float(np.abs(Hs).max()))
        # B(τ) - B(τ') is positive semi-definite for τ > τ': where the largest weight leaves
        # B not positive definite (its entries within the cap), no smaller one makes it so
        # and the ladder is skipped (6 factorizations on a third of a reach's iterates)
        largest = lifted + (AUGMENT[-1] * base) * G
        if np.abs(largest).max() > CURVATURE_MAX or _factorizes(largest, -0.5 * delta):
            for weight in AUGMENT:
                B = lifted + (weight * base) * G
                if _positive(B, delta):
                    C = none.copy()
                    C[rows] = (weight * base / norms[rows, None]) * unit
                    return B, True, C
    return by_eigenvalues(Hs, lifted, held, delta)


def by_eigenvalues(
    Hs: np.ndarray, lifted: np.ndarray, held: np.ndarray, delta: float = DELTA
) -> tuple[np.ndarray, bool, np.ndarray]:
    """:func:`convexified`'s last two ways, for S H S (``Hs``) and S H S + δ I (``lifted``)
    that neither δ nor the τ ladder make positive definite: kept on the held gradients' null
    space and clipped on their span (when some held gradient is not zero), else its
    eigenvalues' magnitudes clipped. The SQP's C loop (:mod:`.native`) makes the first ways
    itself and asks for these."""
    if (np.linalg.norm(held, axis=1) > 0).any():
        blocks = _blocks(lifted, held, delta)
        if blocks is not None:
            return blocks[0], True, blocks[1]
    return _clipped(Hs, delta, flip=True), True, np.zeros((len(held), Hs.shape[0]))


def _clipped(M: np.ndarray, delta: float, flip: bool = False) -> np.ndarray:
    """M with its eigenvalues clipped to [δ, CURVATURE_MAX] (their magnitudes when ``flip``:
    a negative one flipped, not raised to δ)."""
    w, V = np.linalg.eigh(M)
    return (V * np.clip(np.abs(w) if flip else w, delta, CURVATURE_MAX)) @ V.T


def _blocks(
    lifted: np.ndarray, held: np.ndarray, delta: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """(B̃, C) of S H S + δ I (``lifted``) kept on the held gradients' null space and clipped
    on their span, the coupling dropped (see :func:`convexified`); None when they span
    everything or S H S + δ I is not positive definite on their null space."""
    U, sv, Vt = np.linalg.svd(held)
    rank = int(np.sum(sv > 1e-10 * sv[0]))
    if rank >= lifted.shape[0]:
        return None
    Y, Z = Vt[:rank].T, Vt[rank:].T
    reduced = Z.T @ lifted @ Z
    if not _factorizes(reduced, -delta):  # eigenvalues < δ (an eigen solver costs 10x more)
        return None
    B = Z @ reduced @ Z.T + Y @ _clipped(Y.T @ lifted @ Y, delta) @ Y.T
    B = 0.5 * (B + B.T)
    # heldᵀ C ≈ B̃ - S H S - δ I by least squares, through the SVD held = U Σ Vᵀ already
    # made: C = U Σ⁻¹ Yᵀ (B̃ - S H S - δ I) on its rank (np.linalg.lstsq made another)
    C = (U[:, :rank] / sv[:rank]) @ (Y.T @ (B - lifted))
    return B, C
