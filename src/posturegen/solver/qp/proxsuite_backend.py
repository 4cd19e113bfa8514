"""proxsuite's dense ProxQP (Bambade et al. 2022): the fallback when daqp is missing or fails
(an augmented-Lagrangian method, robust on degenerate working sets, slower on small QPs)."""

from __future__ import annotations

import numpy as np

from .base import QP, QPSolution, importable

EPS_ABS = 1e-10
# its outer iterations and the inner ones of each: a fallback QP that daqp failed on is badly
# scaled; unbounded, proxsuite ran 80,000 iterations (7-10 s) on an elastic QP of 62 + 70
# variables, and with its outer iterations bounded at 1000 alone, 374,275 (61 s) on a QP whose
# B̃ reached the SQP's curvature cap (HRP-2's vertical ladder); bounded in both, it says
# "failed" after 323 (0.04 s). The plan corpora and the never-seen families verify the same
MAX_ITER = 100
MAX_ITER_IN = 20
_BIG = 1e20  # proxsuite's "no bound"


class ProxsuiteBackend:
    """The fallback backend."""

    name = "proxsuite"

    def available(self) -> bool:
        return importable("proxsuite")

    def solve(self, qp: QP) -> QPSolution:
        import proxsuite

        n, m = qp.c.size, qp.lbA.size
        # the bounds as rows (the dense backend's box constraints need a recent proxsuite)
        C = np.vstack([np.eye(n), qp.A])
        lower = np.clip(np.concatenate([qp.lb, qp.lbA]), -_BIG, _BIG)
        upper = np.clip(np.concatenate([qp.ub, qp.ubA]), -_BIG, _BIG)
        solver = proxsuite.proxqp.dense.QP(n, 0, n + m)
        solver.settings.eps_abs = EPS_ABS
        solver.settings.max_iter = MAX_ITER
        solver.settings.max_iter_in = MAX_ITER_IN
        solver.settings.verbose = False
        solver.init(qp.B, qp.c, None, None, C, lower, upper)
        solver.solve()
        status = solver.results.info.status
        if status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED:
            name = "solved"
        elif status == proxsuite.proxqp.QPSolverOutput.PROXQP_PRIMAL_INFEASIBLE:
            name = "infeasible"
        else:
            name = "failed"
        z = np.asarray(solver.results.z, dtype=float)
        return QPSolution(
            name,
            np.asarray(solver.results.x, dtype=float),
            z[:n],
            z[n:],
            int(solver.results.info.iter),
        )
