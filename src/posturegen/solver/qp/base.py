"""The dense QP a posture SQP solves at each iterate, and the interface of its backends.

    minimize ½ dᵀ B d + cᵀ d   subject to   lb <= d <= ub,   lbA <= A d <= ubA

with B (n, n) symmetric positive definite, A (m, n) dense; ``equal`` marks the rows of A with
lbA = ubA. A backend returns d, the multipliers of the bounds (n,) and of the rows (m,) in
CasADi's sign convention (B d + c + λ_d + Aᵀ λ_A = 0, λ > 0 at an upper bound, < 0 at a lower
one) and its working set, which warm-starts the next QP of the same shape."""

from __future__ import annotations

import functools
import importlib.util
from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass
class QP:
    """One QP's data (see the module docstring); ``dual_start`` (n + m,): the multipliers of
    a QP of the same shape, whose signs give the first working set (None: cold). B, c and A
    are not written to once a QP holds them: a backend may keep its factorization for the
    next QP that holds the same arrays."""

    B: np.ndarray  # (n, n)
    c: np.ndarray  # (n,)
    A: np.ndarray  # (m, n)
    lb: np.ndarray  # (n,)
    ub: np.ndarray  # (n,)
    lbA: np.ndarray  # (m,)
    ubA: np.ndarray  # (m,)
    equal: np.ndarray  # (m,) bool
    dual_start: np.ndarray | None = None  # (n + m,)


@dataclass(frozen=True)
class QPSolution:
    """A QP's answer: ``status`` "solved", "infeasible" or "failed"."""

    status: str
    d: np.ndarray  # (n,)
    lam_bounds: np.ndarray  # (n,)
    lam_rows: np.ndarray  # (m,)
    iterations: int

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    @property
    def duals(self) -> np.ndarray:
        """(n + m,) the multipliers of the bounds then the rows: a warm start of the next QP."""
        return np.concatenate([self.lam_bounds, self.lam_rows])


class QPBackend(Protocol):
    """A dense QP solver (see :mod:`posturegen.solver.qp.registry`)."""

    name: str

    def available(self) -> bool: ...

    def solve(self, qp: QP) -> QPSolution: ...


@functools.cache
def importable(module: str) -> bool:
    """Whether ``module`` can be imported here (a backend's ``available``); looked up once per
    process (a lookup walks sys.path: 0.3 ms, once per QP of an SQP before this cache)."""
    return importlib.util.find_spec(module) is not None
