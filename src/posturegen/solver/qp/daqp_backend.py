"""daqp: a dual active-set QP solver for dense problems (Arnström, Bemporad, Axehill 2022),
warm-started from the signs of the previous QP's multipliers (its working set).

A workspace (``daqp.Model``) is kept per thread and QP shape: a QP whose B, c and A are the
arrays of the QP of its shape solved before it (the same objects: an SQP's relaxed, corrected
and smaller-region QPs at one iterate) only updates its bounds, which skips B's factorization
and the products with A (a QP of Talos' reach's size, 62 × 95: 28 µs instead of 124 µs)."""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from .base import QP, QPSolution, importable

# daqp's tolerances: the QP's rows are linearized constraints whose nonlinear residual the SQP
# drives below 1e-9 [m, N]; daqp's default primal tolerance (1e-6) would stop it there
PRIMAL_TOL = 1e-10
ITER_LIMIT = 2000
# without proximal regularization (the SQP's B is positive definite) and with the equality
# rows always reduced, as daqp.solve sets them; a workspace's defaults (automatic: on a cold
# solve only) answered "overdetermined initial working set" (-6) on a Talos unload's QP
# that daqp.solve found infeasible at once, and proxsuite, its fallback, then spent 28 s
SETTINGS = {"primal_tol": PRIMAL_TOL, "iter_limit": ITER_LIMIT, "eps_prox": 0.0, "eq_reduction": 1}
# daqp's constraint flags: an equality; a constraint in the first working set (at its upper
# bound; with LOWER, at its lower one)
_EQUALITY, _ACTIVE, _LOWER = 5, 1, 2
_INFEASIBLE = -1  # daqp's exit flag of a QP without a feasible point


# workspaces kept per thread, one per QP shape (n, m): an SQP iterate's QPs share one, its
# θ-max QP (one variable more, :mod:`posturegen.solver.sqp.core`) has its own, so that
# neither sets the other's up again
WORKSPACES = 4


@dataclass
class _Workspace:
    """A daqp workspace and the matrices it was set up with."""

    model: Any = None
    matrices: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


class _Workspaces(threading.local):
    """This thread's workspaces by QP shape, the WORKSPACES last used."""

    def __init__(self) -> None:
        self.by_shape: OrderedDict[tuple[int, int], _Workspace] = OrderedDict()

    def get(self, shape: tuple[int, int]) -> _Workspace:
        ws = self.by_shape.pop(shape, None) or _Workspace()
        self.by_shape[shape] = ws
        while len(self.by_shape) > WORKSPACES:
            self.by_shape.popitem(last=False)
        return ws


class DaqpBackend:
    """The default backend."""

    name = "daqp"

    def __init__(self) -> None:
        self._workspaces = _Workspaces()

    def available(self) -> bool:
        return importable("daqp")

    def solve(self, qp: QP) -> QPSolution:
        sol = self._solved(qp)
        if sol.status == "failed" and qp.dual_start is not None:
            # the first working set was a hint: a failure from it (an overdetermined set,
            # daqp's -6, or cycling) is tried again cold
            sol = self._solved(dataclasses.replace(qp, dual_start=None))
        return sol

    def _solved(self, qp: QP) -> QPSolution:
        import daqp

        n = qp.c.size
        upper = np.concatenate([qp.ub, qp.ubA])
        lower = np.concatenate([qp.lb, qp.lbA])
        sense = _sense(qp, n)
        ws = self._workspaces.get(qp.A.shape)
        last = ws.matrices
        if last is not None and last[0] is qp.B and last[1] is qp.c and last[2] is qp.A:
            flag = ws.model.update(bupper=upper, blower=lower, sense=sense)
        else:
            ws.model, ws.matrices = daqp.Model(), None
            ws.model.settings = SETTINGS
            flag, _ = ws.model.setup(qp.B, qp.c, qp.A, upper, lower, sense)
        if flag < 0:
            ws.matrices = None
            status = "infeasible" if flag == _INFEASIBLE else "failed"
            return QPSolution(status, np.zeros(n), np.zeros(n), np.zeros(qp.lbA.size), 0)
        ws.matrices = (qp.B, qp.c, qp.A)
        d, _fval, flag, info = ws.model.solve()
        lam = np.asarray(info["lam"], dtype=float)
        status = "solved" if flag in (1, 2) else "infeasible" if flag == _INFEASIBLE else "failed"
        if status != "solved":
            lam = np.zeros(upper.size)
        return QPSolution(status, np.asarray(d, dtype=float), lam[:n], lam[n:], info["iterations"])


def _sense(qp: QP, n: int) -> np.ndarray:
    """daqp's flags (n + m,): the equalities, and the first working set from the signs of
    ``dual_start`` (none: cold)."""
    sense = np.zeros(n + qp.lbA.size, dtype=np.int32)
    if qp.dual_start is not None:
        sense[qp.dual_start > 0] = _ACTIVE
        sense[qp.dual_start < 0] = _ACTIVE | _LOWER
    sense[n:][qp.equal] = _EQUALITY
    sense[:n][qp.lb == qp.ub] = _EQUALITY  # a fixed variable (an unloaded contact's forces)
    return sense
