"""The SQP's loop in C (posturegen.solver.sqp.native) against core's loop, its reference: the
same evaluations, the same steps, the same solutions; Python's errors raised through it; core's
loop where it cannot run."""

from __future__ import annotations

import numpy as np
import pytest
from test_sqp import _reach_inputs

from posturegen._cache import Ref
from posturegen._compiler import compiler
from posturegen.solver.sqp import core, native
from posturegen.solver.sqp.core import SQPOptions

needs_cc = pytest.mark.skipif(compiler() is None, reason="no C compiler: core's loop runs")


@needs_cc
@pytest.mark.parametrize("seed", [23, 29, 31])
def test_the_c_loop_takes_cores_steps_on_a_free_reach(seed):
    """A reach without collision rows: the same iterates, to rounding (each iteration's cost,
    violation and region), the same QP iterations and the same solution."""
    oracle, x0, bounds = _reach_inputs(False, seed)
    reference = core.sqp(oracle, x0, bounds, SQPOptions())
    run = native.sqp(oracle, x0, bounds, SQPOptions())
    assert run.status == reference.status == core.SUCCEEDED
    assert run.iterations == reference.iterations and run.qp_iterations == reference.qp_iterations
    assert (run.modified_hessians, run.relaxed_qps) == (
        reference.modified_hessians,
        reference.relaxed_qps,
    )
    np.testing.assert_allclose(run.history, reference.history, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(run.x, reference.x, atol=1e-10)
    np.testing.assert_allclose(run.lam_g, reference.lam_g, atol=1e-8)
    np.testing.assert_array_equal(run.rows_bound, reference.rows_bound)


@needs_cc
@pytest.mark.parametrize("seed", [23, 29, 31])
def test_the_c_loop_finds_cores_solution_with_collision_rows(seed):
    """A reach with its first active set's collision rows: the same solution and multipliers;
    the path may differ where a decision is within rounding of its threshold (seed 29: 13
    iterations against core's 15), so the iterations only within a few."""
    oracle, x0, bounds = _reach_inputs(True, seed)
    reference = core.sqp(oracle, x0, bounds, SQPOptions())
    run = native.sqp(oracle, x0, bounds, SQPOptions())
    assert run.status == reference.status == core.SUCCEEDED
    assert abs(run.iterations - reference.iterations) <= 3
    assert run.history[0] == pytest.approx(reference.history[0], rel=1e-12)  # the same start
    np.testing.assert_allclose(run.x, reference.x, atol=1e-6)
    np.testing.assert_allclose(run.lam_g, reference.lam_g, atol=1e-4)


@needs_cc
def test_the_c_loop_evaluates_the_oracles_functions():
    """After one iteration from x0 with multipliers, the kernel's first iterate holds the
    oracle's f, ∇f, g and J at x0 and its model the oracle's ∇²L at x0, bit for bit."""
    oracle, x0, bounds = _reach_inputs(True, 23)
    rng = np.random.default_rng(0)
    lam = rng.standard_normal(oracle.m)
    x = np.clip(x0, bounds.lbx, bounds.ubx)
    native.sqp(oracle, x0, bounds, SQPOptions(max_iter=1), lam_g0=lam)
    kernel = native._KERNELS.get(Ref(oracle))
    assert kernel is not None and kernel.s.iterations == 1
    f, grad, g, J = (np.copy(v) for v in oracle.first_order(x))
    H = oracle.hessian(x, 1.0, lam)
    a = kernel.a  # the start is the first slot's; a trial point took the other
    np.testing.assert_array_equal(a["X"][0], x)
    assert a["F"][0] == f
    np.testing.assert_array_equal(a["GRAD"][0], grad)
    np.testing.assert_array_equal(a["G"][0], g)
    np.testing.assert_array_equal(a["JAC"][0], J)
    np.testing.assert_array_equal(a["H"], H)


@needs_cc
def test_an_error_in_python_is_raised_through_the_c_loop(monkeypatch):
    """A QP's Python that raises ends the C loop and the error reaches the caller (not a
    silent run); the kernel then runs again."""
    oracle, x0, bounds = _reach_inputs(False, 23)

    def broken(*args, **kwargs):
        raise RuntimeError("a QP backend broke")

    monkeypatch.setattr(core, "_relaxed", broken)
    with pytest.raises(RuntimeError, match="a QP backend broke"):
        native.sqp(oracle, x0, bounds, SQPOptions())
    monkeypatch.undo()
    assert native.sqp(oracle, x0, bounds, SQPOptions()).status == core.SUCCEEDED


def test_without_the_c_loop_cores_runs(monkeypatch):
    """POSTUREGEN_NO_NATIVE_SQP (or no C compiler): core's loop, the same run bit for bit."""
    oracle, x0, bounds = _reach_inputs(False, 29)
    monkeypatch.setenv("POSTUREGEN_NO_NATIVE_SQP", "1")
    native._library.cache_clear()
    try:
        assert not native.available()
        run = native.sqp(oracle, x0, bounds, SQPOptions())
        reference = core.sqp(oracle, x0, bounds, SQPOptions())
        np.testing.assert_array_equal(run.x, reference.x)
        assert run.history == reference.history
    finally:
        native._library.cache_clear()


@needs_cc
@pytest.mark.parametrize(
    "options",
    [SQPOptions(max_time_s=1e-9), SQPOptions(max_iter=0), SQPOptions(max_iter=3)],
    ids=["out of time", "no iteration", "three iterations"],
)
def test_the_c_loop_stops_where_core_stops(options):
    """The run's limits: out of time before its first iteration, no iteration allowed, three:
    the same status, iterations and iterate as core's."""
    oracle, x0, bounds = _reach_inputs(True, 23)
    reference = core.sqp(oracle, x0, bounds, options)
    run = native.sqp(oracle, x0, bounds, options)
    assert run.status == reference.status != core.SUCCEEDED
    assert run.iterations == reference.iterations and len(run.history) == len(reference.history)
    np.testing.assert_allclose(run.x, reference.x, atol=1e-12)
