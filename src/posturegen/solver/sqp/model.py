"""The SQP's QP model at an iterate, in the scaled variables d̃ = d / s (radians, metres,
newtons / robot weight): the Hessian of the Lagrangian made positive definite where it is
evaluated (:mod:`.hessian`) and carried by a damped BFGS update between two evaluations, the
cost's gradient and the rows' Jacobian; and the QP's multipliers corrected by what the
convexification adds (:func:`corrected`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..qp.base import QPSolution
from .hessian import CURVATURE_MAX, convexified
from .iterate import Bounds, Iterate
from .oracle import Oracle


@dataclass(frozen=True)
class Model:
    """The QP's model at an iterate, in the scaled variables d̃ = d / s: B̃ = S B S, c̃ = S ∇f,
    Ã = J S, and the rows and bounds that B̃ holds (hessian.convexified): where those hold at
    the QP's solution, its multipliers λ' are the program's λ' + C d̃ (rows, then bounds)."""

    B: np.ndarray  # (n, n)
    c: np.ndarray  # (n,)
    A: np.ndarray  # (m, n)
    rows: np.ndarray  # (m,) bool: the rows held
    held_x: np.ndarray  # (n,) bool: the bounds held
    C: np.ndarray  # (rows + bounds held, n)
    modified: bool = False  # B̃ is not S ∇²L S + δ I (hessian.convexified)


def model_at(
    oracle: Oracle, it: Iterate, lam_g: np.ndarray, lam_x: np.ndarray, bounds: Bounds
) -> Model:
    """The QP's model at ``it`` in the scaled variables: ∇²L made positive definite (first
    on the null space of the rows and bounds that hold: the equality rows and those with a
    multiplier), ∇f and J."""
    As = it.J * bounds.scale
    rows = bounds.equal | (lam_g != 0)  # (m,)
    held_x = lam_x != 0  # (n,) the variables at a bound of their own
    unit = np.eye(len(held_x))[held_x]
    Bs, modified, C = convexified(
        oracle.hessian(it.x, 1.0, lam_g), bounds.scale, np.vstack([As[rows], unit])
    )
    return Model(Bs, it.grad * bounds.scale, As, rows, held_x, C, modified)


def relinearized(
    model: Model, previous: Iterate, it: Iterate, lam_g: np.ndarray, bounds: Bounds
) -> Model:
    """The QP model at ``it`` between two Hessian evaluations (HESSIAN_EVERY): ``model``'s B̃
    updated along the step from ``previous`` (:func:`damped_bfgs`, s̃ = (x₊ - x) / s and ỹ =
    S (∇L(x₊) - ∇L(x)) at the step's multipliers), c̃ = S ∇f and Ã = J S of ``it``. B̃'s
    correction C is not carried (it is of the rows held where B̃ was made): the QP's
    multipliers are those of B̃, exact at a step of zero."""
    scale = bounds.scale
    s = (it.x - previous.x) / scale
    y = scale * ((it.grad + it.J.T @ lam_g) - (previous.grad + previous.J.T @ lam_g))
    B = damped_bfgs(model.B, s, y)
    return Model(
        B, it.grad * scale, it.J * scale, model.rows, model.held_x, np.zeros((0, it.x.size))
    )


def damped_bfgs(B: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Powell's damped BFGS update of the positive definite B (n, n) along s with y:
    B - B s sᵀB / sᵀBs + r rᵀ / sᵀr, r = θ y + (1 - θ) B s, θ = 1 when sᵀy >= 0.2 sᵀBs, else
    0.8 sᵀBs / (sᵀBs - sᵀy) (so that sᵀr >= 0.2 sᵀBs: positive definite). B itself when the
    step is nothing or the update's entries pass CURVATURE_MAX."""
    Bs = B @ s
    sBs = float(s @ Bs)
    if sBs <= 1e-300:
        return B
    sy = float(s @ y)
    theta = 1.0 if sy >= 0.2 * sBs else 0.8 * sBs / (sBs - sy)
    r = theta * y + (1 - theta) * Bs
    removed = np.outer(Bs, Bs)
    removed /= sBs
    added = np.outer(r, r)
    added /= float(s @ r)
    updated = np.subtract(B, removed, out=removed)
    updated += added
    return updated if np.abs(updated, out=added).max() <= CURVATURE_MAX else B


def corrected(sol: QPSolution, model: Model, equal: np.ndarray, scale: np.ndarray) -> QPSolution:
    """The multipliers of a QP solved on B̃ (its solution in the variables' units): the
    program's, λ' + C d̃, where the rows and bounds that B̃ holds hold at the solution (an
    equality, or a multiplier of their own)."""
    if not model.C.any():
        return sol
    extra = model.C @ (sol.d / scale)  # (k,) in the scaled QP's units
    k = int(model.rows.sum())
    lam_rows, lam_bounds = sol.lam_rows.copy(), sol.lam_bounds.copy()
    active = (lam_rows[model.rows] != 0) | equal[model.rows]
    lam_rows[model.rows] += np.where(active, extra[:k], 0.0)
    at_bound = lam_bounds[model.held_x] != 0
    lam_bounds[model.held_x] += np.where(at_bound, extra[k:] / scale[model.held_x], 0.0)
    return dataclasses.replace(sol, lam_rows=lam_rows, lam_bounds=lam_bounds)
