"""daqp: a dual active-set QP solver for dense problems (Arnström, Bemporad, Axehill 2022),
warm-started from the signs of the previous QP's multipliers (its working set)."""

from __future__ import annotations

import numpy as np

from .base import QP, QPSolution, importable

# daqp's tolerances: the QP's rows are linearized constraints whose nonlinear residual the SQP
# drives below 1e-9 [m, N]; daqp's default primal tolerance (1e-6) would stop it there
PRIMAL_TOL = 1e-10
ITER_LIMIT = 2000
_EQUALITY, _INEQUALITY = 5, 0


class DaqpBackend:
    """The default backend."""

    name = "daqp"

    def available(self) -> bool:
        return importable("daqp")

    def solve(self, qp: QP) -> QPSolution:
        import daqp

        n = qp.c.size
        upper = np.concatenate([qp.ub, qp.ubA])
        lower = np.concatenate([qp.lb, qp.lbA])
        sense = np.zeros(upper.size, dtype=np.int32)
        sense[n:][qp.equal] = _EQUALITY
        d, _fval, flag, info = daqp.solve(
            qp.B,
            qp.c,
            qp.A,
            upper,
            lower,
            sense,
            primal_tol=PRIMAL_TOL,
            iter_limit=ITER_LIMIT,
            dual_start=qp.dual_start,
        )
        lam = np.asarray(info["lam"], dtype=float)
        status = "solved" if flag in (1, 2) else "infeasible" if flag == -1 else "failed"
        if status != "solved":
            lam = np.zeros(upper.size)
        return QPSolution(status, np.asarray(d, dtype=float), lam[:n], lam[n:], info["iterations"])
