"""posturegen.solver.buffered: a CasADi function called into numpy arrays gives what its
ordinary call gives (dense and sparse outputs, an nlpsol's solution and statistics)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from posturegen.solver.buffered import Buffered


def test_a_buffered_call_gives_the_functions_values_dense_and_sparse():
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    sparse = ca.SX(3, 2)  # a (3, 2) output with structural zeros
    sparse[0, 0], sparse[2, 1] = x[0] * p[1], ca.sin(x[2])
    fn = ca.Function("f", [x, p], [ca.dot(x, x) + p[0], sparse], ["x", "p"], ["f", "s"])
    call = Buffered(fn)
    rng = np.random.default_rng(0)
    for _ in range(3):  # the same arrays, new values each time
        xv, pv = rng.normal(size=3), rng.normal(size=2)
        call.arg("x")[:] = xv
        call.arg("p")[:] = pv
        call()
        expected = fn(xv, pv)
        assert call.res("f")[0] == float(expected[0])
        np.testing.assert_array_equal(call.column(1), np.array(expected[1]).ravel(order="F"))


def test_a_buffered_nlpsol_solves_and_reports_its_statistics():
    """min (x0 - p)² + x1² s.t. x0 + x1 = 1: x = ((1 + p) / 2, (1 - p) / 2)."""
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p")
    nlp = {"x": x, "p": p, "f": (x[0] - p) ** 2 + x[1] ** 2, "g": x[0] + x[1]}
    solver = ca.nlpsol("s", "ipopt", nlp, {"print_time": False, "ipopt.print_level": 0})
    call = Buffered(solver)
    call.arg("lbg")[:] = call.arg("ubg")[:] = 1.0
    call.arg("lbx")[:], call.arg("ubx")[:] = -np.inf, np.inf
    for value in (0.0, 3.0):
        call.arg("p")[:] = value
        call()
        np.testing.assert_allclose(call.res("x"), [(1 + value) / 2, (1 - value) / 2], atol=1e-8)
        assert call.stats()["return_status"] == "Solve_Succeeded"
