"""The program's functions at one parameter vector, dense, for the SQP: the cost f, its
gradient ∇f (n,), the constraints g (m,), their Jacobian J (m, n) and the Hessian of the
Lagrangian ∇²(σ f + λᵀ g) (n, n). They are the functions IPOPT calls (generated C when the
structure's library is built, :mod:`posturegen.solver.codegen`), taken from its solver and
evaluated through CasADi's buffers (:mod:`posturegen.solver.buffered`): the inputs and
outputs are numpy arrays written in place (a call through ``Function.call`` and ``DM.full``
cost 74 µs more each, more than the generated code of Talos' Jacobian itself)."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..buffered import Buffered


@dataclass(frozen=True)
class Parts:
    """What evaluates an oracle from C (:mod:`.native`): its calls, their input arrays, and
    where each output's nonzeros go in its dense form (flat, row-major)."""

    grad: Buffered  # nlp_grad_f: f, ∇f
    jac: Buffered  # nlp_jac_g: g, J
    hess: Buffered  # nlp_hess_l: ∇²L's upper triangle
    x: np.ndarray  # (n,) the calls' x
    sigma: np.ndarray  # (1,) the Hessian's σ
    lam: np.ndarray  # (m,) the Hessian's λ
    at_grad: np.ndarray  # ∇f's nonzeros in (n,)
    at_g: np.ndarray  # g's nonzeros in (m,)
    at_jac: np.ndarray  # J's nonzeros in (m, n)
    at_upper: np.ndarray  # ∇²L's nonzeros in (n, n)
    at_mirrored: np.ndarray  # the off-diagonal ones mirrored
    off: np.ndarray  # which nonzeros those are (indices)


class Oracle:
    """f, ∇f, g, J and ∇²L of a compiled structure at parameters ``p``; the arrays returned
    are the oracle's own and change at its next call of the same kind."""

    def __init__(self, solver: ca.Function, p: np.ndarray) -> None:
        grad_f = solver.get_function("nlp_grad_f")
        self.n = int(grad_f.size1_out(1))
        g_fn = solver.get_function("nlp_g")
        self.m = int(g_fn.size1_out(0))
        self._x = np.zeros(self.n)
        self._p = np.array(p, dtype=float).ravel()
        self._sigma = np.ones(1)
        self._lam = np.zeros(self.m)
        xp = [self._x, self._p]
        self._f = Buffered(solver.get_function("nlp_f"), xp)
        self._g = Buffered(g_fn, xp)
        self._grad = Buffered(grad_f, xp)
        self._jac = Buffered(solver.get_function("nlp_jac_g"), xp)
        self._hess = Buffered(solver.get_function("nlp_hess_l"), [*xp, self._sigma, self._lam])
        self._dense = {
            "g": (self._g.scatter(0), np.zeros(self.m)),
            "grad": (self._grad.scatter(1), np.zeros(self.n)),
            "g_jac": (self._jac.scatter(0), np.zeros(self.m)),
            "jac": (self._jac.scatter(1), np.zeros((self.m, self.n))),
        }
        self._hess_at = _symmetric_at(self._hess.sparsity[0])
        self.evaluations = 0

    def parts(self) -> Parts:
        """What evaluates this oracle from C: its calls, inputs and dense positions."""
        upper, mirrored, off = self._hess_at
        return Parts(
            self._grad,
            self._jac,
            self._hess,
            self._x,
            self._sigma,
            self._lam,
            self._grad.positions(1),
            self._jac.positions(0),
            self._jac.positions(1),
            upper,
            mirrored,
            np.flatnonzero(off),
        )

    def set_parameters(self, p: np.ndarray) -> Oracle:
        """Evaluate at parameters ``p`` from now on (the same structure: buffers reused)."""
        self._p[:] = np.asarray(p, dtype=float).ravel()
        return self

    def _dense_of(self, name: str, nonzeros: np.ndarray) -> np.ndarray:
        write, out = self._dense[name]
        write(nonzeros, out)
        return out.copy()

    def first_order(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """f, ∇f (n,), g (m,) and J (m, n) at x."""
        self._x[:] = x
        self.evaluations += 2
        f_nz, grad_nz = self._grad()
        g_nz, jac_nz = self._jac()
        return (
            float(f_nz[0]),
            self._dense_of("grad", grad_nz),
            self._dense_of("g_jac", g_nz),
            self._dense_of("jac", jac_nz),
        )

    def hessian(self, x: np.ndarray, sigma: float, lam_g: np.ndarray) -> np.ndarray:
        """∇²(σ f + λᵀ g) (n, n) at x, symmetric (the functions give its upper triangle)."""
        self._x[:] = x
        self._sigma[0] = sigma
        self._lam[:] = lam_g
        self.evaluations += 1
        upper, mirrored, off = self._hess_at
        nonzeros = self._hess()[0]
        H = np.zeros((self.n, self.n))
        flat = H.ravel()  # a view
        flat[upper] = nonzeros
        flat[mirrored] = nonzeros[off]
        return H


def _symmetric_at(sparsity: ca.Sparsity) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the nonzeros of a symmetric matrix given by one triangle (CasADi's ``sparsity``:
    nlp_hess_l gives the upper one) go in its flat (row-major) dense form: their own places,
    the mirrored places of those off the diagonal, and which those are."""
    rows, cols = (np.asarray(v, dtype=np.intp) for v in sparsity.get_triplet())
    n = sparsity.size2()
    off = rows != cols
    return rows * n + cols, cols[off] * n + rows[off], off
