"""The SQP core (posturegen.solver.sqp): its QP backends, the Hessian's convexification, the
postures it finds (IPOPT's, verified), the solver option, row order, warm starts and the
fallback to IPOPT."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from posturegen import solve
from posturegen.bench.reach import reach_balance_family
from posturegen.cli import _solvers
from posturegen.errors import InputError, PosturegenError
from posturegen.solver import runs as runs_module
from posturegen.solver.inspection import initial_collision_term
from posturegen.solver.problem import Program, SolverOptions
from posturegen.solver.qp import proxsuite_backend, registry
from posturegen.solver.qp.base import QP, QPSolution
from posturegen.solver.qp.proxsuite_backend import ProxsuiteBackend
from posturegen.solver.runs import variable_scales
from posturegen.solver.sqp import core
from posturegen.solver.sqp.core import (
    LINEAR_TOL,
    Bounds,
    Iterate,
    SQPOptions,
    SQPRun,
    _Flat,
    _Promise,
    _reachable,
    _relaxed,
    _theta_max,
    sqp,
)
from posturegen.solver.sqp.hessian import AUGMENT, CURVATURE_MAX, DELTA, convexified
from posturegen.solver.sqp.model import Model, corrected
from posturegen.solver.sqp.oracle import Oracle


def _random_qp(rng: np.random.Generator, n: int = 12, m: int = 9) -> QP:
    """A strictly convex QP with a feasible point: 2 equality rows, 2 one-sided, the others
    two-sided, and bounds."""
    M = rng.normal(size=(n, n))
    A = rng.normal(size=(m, n))
    inside = A @ rng.uniform(-0.2, 0.2, n)
    lbA, ubA = inside - rng.uniform(0.0, 0.3, m), inside + rng.uniform(0.0, 0.3, m)
    lbA[:2] = ubA[:2] = inside[:2]
    ubA[2:4] = np.inf
    c = 5.0 * rng.normal(size=n)  # far from the box's centre: bounds and rows become active
    box = np.full(n, 0.3)
    return QP(M @ M.T + np.eye(n), c, A, -box, box, lbA, ubA, lbA == ubA)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_qp_backends_agree_and_meet_kkt(seed):
    """Each backend: B d + c + λ_d + Aᵀλ_A = 0, the rows and bounds hold, a multiplier only
    on a bound that holds with equality and of its sign; the backends agree."""
    qp = _random_qp(np.random.default_rng(seed))
    solutions = {name: registry.backend(name).solve(qp) for name in registry.available()}
    assert set(solutions) == {"daqp", "proxsuite"}
    for name, sol in solutions.items():
        assert sol.solved, name
        residual = qp.B @ sol.d + qp.c + sol.lam_bounds + qp.A.T @ sol.lam_rows
        assert np.abs(residual).max() < 1e-6, name
        Ad = qp.A @ sol.d
        assert np.all(Ad >= qp.lbA - 1e-7) and np.all(Ad <= qp.ubA + 1e-7), name
        assert np.all(sol.lam_rows[Ad < qp.ubA - 1e-6] <= 1e-6), name
        assert np.all(sol.lam_rows[Ad > qp.lbA + 1e-6] >= -1e-6), name
        assert np.all(sol.lam_bounds[sol.d < qp.ub - 1e-6] <= 1e-6), name
        assert np.all(sol.lam_bounds[sol.d > qp.lb + 1e-6] >= -1e-6), name
        assert np.abs(sol.lam_bounds).max() > 1e-3  # the test reaches the bounds
    np.testing.assert_allclose(solutions["daqp"].d, solutions["proxsuite"].d, atol=1e-6)


def test_daqp_reuses_its_workspace_only_for_the_same_matrices():
    """QPs at one iterate (the same B, c and A objects, other bounds, a working set or none)
    solved on the workspace give what a fresh workspace gives; a QP with equal values in new
    arrays is set up again; an infeasible one in between does not spoil the next."""
    rng = np.random.default_rng(7)
    qp = _random_qp(rng)
    daqp = registry.backend("daqp")
    first = daqp.solve(qp)
    assert first.solved
    variants = []
    for scale in (0.5, 0.1, 2.0):
        lbA, ubA = qp.lbA * scale, qp.ubA * scale
        variants.append(dataclasses.replace(qp, lbA=lbA, ubA=ubA, dual_start=first.duals))
        variants.append(dataclasses.replace(qp, lb=qp.lb * scale, ub=qp.ub * scale))
    bad = dataclasses.replace(qp, lbA=qp.lbA.copy())
    bad.lbA[4] = 1e3
    for v in (*variants[:2], bad, *variants[2:]):
        reused = daqp.solve(v)
        fresh = registry.backend("daqp").__class__().solve(v)
        assert reused.status == fresh.status
        np.testing.assert_allclose(reused.d, fresh.d, atol=1e-9)
        np.testing.assert_allclose(reused.duals, fresh.duals, atol=1e-9)
    copied = dataclasses.replace(variants[0], B=qp.B.copy() * 2.0, c=qp.c.copy(), A=qp.A.copy())
    again = daqp.solve(copied)
    fresh = registry.backend("daqp").__class__().solve(copied)
    np.testing.assert_allclose(again.d, fresh.d, atol=1e-9)
    assert np.abs(again.d - daqp.solve(variants[0]).d).max() > 1e-6  # B doubled: another step


def _recorded_qp(name: str) -> QP:
    """A QP an SQP run met, saved in tests/data (its rows with lbA == ubA are equalities)."""
    data = np.load(Path(__file__).parent / "data" / name)
    arrays = (data[k] for k in ("B", "c", "A", "lb", "ub", "lbA", "ubA"))
    return QP(*arrays, data["lbA"] == data["ubA"])


def test_an_unloads_qp_is_infeasible_at_once_not_failed(monkeypatch):
    """A QP of the SQP on Talos' unload off the ground (stairs plan; dependent equality rows,
    38 free collision rows): daqp says infeasible without the fallback. With a workspace's
    default settings daqp answered "overdetermined initial working set" and proxsuite then
    ran 28 s."""
    qp = _recorded_qp("unload_qp.npz")
    asked = []
    proxsuite = registry.backend("proxsuite")
    monkeypatch.setattr(proxsuite, "solve", lambda q: asked.append(q) or None)
    assert registry.solve(qp).status == "infeasible"
    assert not asked


def test_proxsuite_gives_up_on_a_capped_curvature_qp_within_its_iteration_bound():
    """A QP of the SQP on HRP-2's vertical-ladder unload whose B̃ reached the curvature cap
    (eigenvalues 1e-4 to 1e8): daqp fails on it, and proxsuite, its fallback, bounded only in
    its outer iterations, ran 374,275 iterations (61 s) to fail too. Bounded in both, it
    fails after at most MAX_ITER · MAX_ITER_IN."""
    sol = ProxsuiteBackend().solve(_recorded_qp("capped_curvature_qp.npz"))
    assert sol.status != "solved"
    assert sol.iterations <= proxsuite_backend.MAX_ITER * proxsuite_backend.MAX_ITER_IN


def test_a_solution_that_is_not_finite_is_a_failure(monkeypatch):
    """A backend's "solved" with NaN is failed: the next backend answers."""

    class Broken:
        name = "broken"

        def available(self) -> bool:
            return True

        def solve(self, qp: QP) -> QPSolution:
            return QPSolution("solved", np.full(qp.c.size, np.nan), qp.c * 0, qp.lbA * 0, 1)

    monkeypatch.setitem(registry._BACKENDS, "broken", Broken())
    qp = _random_qp(np.random.default_rng(5))
    sol = registry.solve(qp, "broken")
    assert sol.solved and np.all(np.isfinite(sol.d))


def test_infeasible_qp_is_reported_not_solved():
    qp = _random_qp(np.random.default_rng(3))
    qp.lbA[4], qp.ubA[4] = 1e3, np.inf  # a row no point of the box reaches
    assert registry.solve(qp).status == "infeasible"


def test_convexified_lifts_semidefinite_and_flips_negative_curvature():
    """In the scaled variables: δ added where S H S is positive semi-definite, else (no row
    held) the negative eigenvalues flipped, those below δ raised to δ, every eigenvector
    kept."""
    rng = np.random.default_rng(4)
    scale = np.concatenate([np.ones(6), np.full(4, 900.0)])
    M = rng.normal(size=(6, 6))
    H = np.zeros((10, 10))
    H[:6, :6] = M @ M.T + np.eye(6)  # positive on the first block, zero on the "forces"
    none = np.zeros((0, 10))  # no row or bound held
    Bs, modified, _ = convexified(H, scale, none)
    assert not modified
    S = np.outer(scale, scale)
    np.testing.assert_allclose(Bs, H * S + DELTA * np.eye(10), rtol=1e-12, atol=1e-15)
    H[0, 0] = -50.0  # negative curvature
    Bs, modified, _ = convexified(H, scale, none)
    assert modified
    w, V = np.linalg.eigh(H * S)
    assert np.linalg.eigvalsh(Bs).min() >= DELTA * (1 - 1e-9)
    assert w.min() < -DELTA
    np.testing.assert_allclose(Bs @ V, V * np.maximum(np.abs(w), DELTA), atol=1e-8)


def _indefinite_with_held_rows(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """H (8, 8) with one negative eigenvalue along a direction that rows A (2, 8) hold: H
    positive definite on A's null space."""
    A = rng.normal(size=(2, 8))
    M = rng.normal(size=(8, 8))
    H = M @ M.T + np.eye(8) - 60.0 * np.outer(A[0], A[0]) / (A[0] @ A[0])
    assert np.linalg.eigvalsh(H).min() < 0
    return H, A


def test_convexified_keeps_the_curvature_on_the_null_space_of_the_rows_held():
    """With rows held (their gradients in the scaled variables), B̃ = S H S + δ I + τ ÂᵀÂ for
    the smallest τ of AUGMENT that makes it positive definite: equal to S H S + δ I on their
    null space, and C d̃ = τ (Â d̃) / ‖row‖; a direction the rows do not hold gets flipped."""
    rng = np.random.default_rng(8)
    H, A = _indefinite_with_held_rows(rng)
    scale = np.ones(8)
    held = 3.0 * A  # the rows' norms do not matter
    Bs, modified, C = convexified(H, scale, held)
    assert modified
    assert np.linalg.eigvalsh(Bs).min() >= 0.5 * DELTA
    Z = np.linalg.svd(A)[2][2:].T  # (8, 6) the rows' null space
    np.testing.assert_allclose(Z.T @ Bs @ Z, Z.T @ (H + DELTA * np.eye(8)) @ Z, atol=1e-9)
    np.testing.assert_allclose(held.T @ C, Bs - H - DELTA * np.eye(8), atol=1e-8)
    tau = np.sum(C * held, axis=1)  # τ of each row
    weight = tau[0] / max(1.0, np.abs(H).max())
    assert tau[1] == pytest.approx(tau[0]) and any(weight == pytest.approx(w) for w in AUGMENT)
    unit = A / np.linalg.norm(A, axis=1)[:, None]
    for w in [w for w in AUGMENT if w < weight * (1 - 1e-9)]:  # a smaller one would not do
        B = H + DELTA * np.eye(8) + w * max(1.0, np.abs(H).max()) * unit.T @ unit
        assert np.linalg.eigvalsh(B - 0.5 * DELTA * np.eye(8)).min() < 0
    H_free = H - 60.0 * np.eye(8)  # negative on the null space too: flipped instead
    Bs, modified, C = convexified(H_free, scale, A)
    assert modified and not C.any()
    w, V = np.linalg.eigh(H_free)
    assert w.min() < -DELTA
    np.testing.assert_allclose(Bs @ V, V * np.maximum(np.abs(w), DELTA), atol=1e-8)


def _coupled(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """H (6, 6) positive definite on the null space of rows A (2, 6), negative on their span
    and coupled to the null space so strongly (1e3) that only τ ≈ 1e6 would make
    H + τ ÂᵀÂ positive, beyond AUGMENT's largest (100 max |H|)."""
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    Y, Z = Q[:, :2], Q[:, 2:]
    K = 1e3 * rng.uniform(0.5, 1.0, size=(2, 4))
    H = -Y @ Y.T + Z @ Z.T + Y @ K @ Z.T + Z @ K.T @ Y.T
    A = rng.normal(size=(2, 2)) @ Y.T  # rows spanning Y
    return H, A


def test_convexified_keeps_the_null_space_when_no_weight_is_enough():
    """Where no τ of AUGMENT makes S H S + δ I + τ ÂᵀÂ positive (strong coupling) but S H S is
    positive on the rows' null space: B̃ keeps S H S + δ I there, clips it on the rows' span
    and drops the coupling; C by least squares: heldᵀ C d̃ = (B̃ - S H S - δ I) d̃ for every
    d̃ that keeps the rows (on their null space)."""
    H, A = _coupled(np.random.default_rng(10))
    Bs, modified, C = convexified(H, np.ones(6), A)
    assert modified
    assert np.linalg.eigvalsh(Bs).min() >= 0.5 * DELTA
    Z = np.linalg.svd(A)[2][2:].T
    lifted = H + DELTA * np.eye(6)
    np.testing.assert_allclose(Z.T @ Bs @ Z, Z.T @ lifted @ Z, atol=1e-8)
    np.testing.assert_allclose(Bs @ Z, Z @ (Z.T @ lifted @ Z), atol=1e-8)  # no coupling
    np.testing.assert_allclose(A.T @ C @ Z, (Bs - lifted) @ Z, atol=1e-6)


@pytest.mark.parametrize("make", [_indefinite_with_held_rows, _coupled])
def test_a_qp_on_the_convexified_hessian_gives_newtons_step_and_the_programs_multipliers(make):
    """An equality-constrained QP (rows holding at d = 0) whose H is indefinite but positive
    on the rows' null space: solved on B̃ (rows held), its step is the one of H itself
    (lifted by δ), and its multipliers corrected by C d̃ satisfy (H + δ I) d + c + Aᵀλ = 0."""
    H, A = make(np.random.default_rng(9))
    n = H.shape[0]
    c = np.random.default_rng(11).normal(size=n)
    Bs, _, C = convexified(H, np.ones(n), A)
    box, b = np.full(n, 1e3), np.zeros(2)
    qp = QP(Bs, c, A, -box, box, b, b.copy(), np.ones(2, dtype=bool))
    sol = registry.solve(qp)
    assert sol.solved
    H = H + DELTA * np.eye(n)
    kkt = np.block([[H, A.T], [A, np.zeros((2, 2))]])
    newton = np.linalg.solve(kkt, np.concatenate([-c, b]))
    np.testing.assert_allclose(sol.d, newton[:n], rtol=1e-6, atol=1e-8)
    model = Model(Bs, c, A, np.ones(2, dtype=bool), np.zeros(n, dtype=bool), C)
    fixed = corrected(sol, model, qp.equal, np.ones(n))
    size = max(1.0, float(np.abs(fixed.lam_rows).max()))
    np.testing.assert_allclose(H @ sol.d + c + A.T @ fixed.lam_rows, 0.0, atol=1e-6 * size)
    np.testing.assert_allclose(fixed.lam_rows, newton[n:], rtol=1e-6, atol=1e-6)


def test_convexified_caps_runaway_curvature():
    """A Hessian whose multipliers ran away (an eigenvalue 1e10 in scaled variables): that
    eigenvalue is cut to CURVATURE_MAX, the others and the eigenvectors kept."""
    rng = np.random.default_rng(6)
    Q, _ = np.linalg.qr(rng.normal(size=(8, 8)))
    w = np.array([1e10, 3e4, 50.0, 2.0, 1.0, 0.5, 0.1, 0.01])
    H = (Q * w) @ Q.T
    Bs, modified, _ = convexified(H, np.ones(8), np.zeros((0, 8)))
    assert modified
    np.testing.assert_allclose(Bs @ Q, Q * np.minimum(w, CURVATURE_MAX), rtol=1e-6, atol=1e-3)


def _with(problem, **options):
    return dataclasses.replace(
        problem, solver_options=dataclasses.replace(problem.solver_options, **options)
    )


@pytest.fixture(scope="module")
def free_problems():
    return list(reach_balance_family(False)(4, 21))


def test_sqp_finds_ipopts_verified_postures(free_problems):
    for problem in free_problems[:3]:
        by_sqp = solve(_with(problem, method="sqp"))
        by_ipopt = solve(_with(problem, method="ipopt"))
        assert by_sqp.success and by_ipopt.success, (by_sqp.message, by_ipopt.message)
        assert by_sqp.method == "sqp" and by_ipopt.method == "ipopt"
        assert by_sqp.iterations_by_method == {"sqp": by_sqp.iterations}
        assert abs(by_sqp.cost - by_ipopt.cost) <= 1e-6 * max(1.0, abs(by_ipopt.cost))
        np.testing.assert_allclose(by_sqp.q, by_ipopt.q, atol=1e-4)


class _Permuted:
    """An oracle whose constraint rows come in another order."""

    def __init__(self, oracle: Oracle, order: np.ndarray) -> None:
        self.oracle, self.order = oracle, order
        self.n, self.m = oracle.n, oracle.m

    def first_order(self, x):
        f, grad, g, J = self.oracle.first_order(x)
        return f, grad, g[self.order], J[self.order]

    def hessian(self, x, sigma, lam_g):
        lam = np.empty_like(lam_g)
        lam[self.order] = lam_g
        return self.oracle.hessian(x, sigma, lam)

    def bounds(self, bounds: Bounds) -> Bounds:
        """``bounds`` with the rows' in this oracle's order."""
        order = self.order
        return Bounds(bounds.lbx, bounds.ubx, bounds.lbg[order], bounds.ubg[order], bounds.scale)


def _core_inputs(program: Program):
    compiled = program.compile()
    compiled.refresh()
    x0, p, lbg, ubg = program.numeric(compiled)
    scales = variable_scales(compiled, program.robot.weight)
    return Oracle(compiled.solver, p), x0, Bounds(compiled.lbx, compiled.ubx, lbg, ubg, scales)


def _reach_inputs(collision: bool, seed: int):
    """The SQP core's inputs for a reach-balance problem of ``seed``, with its first active
    set's collision rows when ``collision``."""
    problem = next(iter(reach_balance_family(collision)(1, seed)))
    program = Program.of(problem)
    if collision:
        _active, term = initial_collision_term(problem)
        program = Program.of(problem, collision_term=term)
    return _core_inputs(program)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_oracles_derivatives_match_finite_differences(seed):
    """The SQP's oracle on a reach with its collision rows, at a seeded point near its start
    with seeded multipliers: J and ∇f against central differences of g and f, ∇²L (the
    functions' upper triangle made symmetric) against central differences of ∇f + Jᵀλ."""
    oracle, x0, bounds = _reach_inputs(True, 23)
    rng = np.random.default_rng(seed)
    x = np.clip(x0 + 0.05 * bounds.scale * rng.standard_normal(oracle.n), bounds.lbx, bounds.ubx)
    lam = rng.standard_normal(oracle.m)
    f, grad, g, J = (np.copy(v) for v in oracle.first_order(x))
    H = oracle.hessian(x, 1.0, lam)
    np.testing.assert_array_equal(H, H.T)
    h = 1e-6
    fd_J, fd_grad, fd_H = np.zeros_like(J), np.zeros_like(grad), np.zeros_like(H)
    for k in range(oracle.n):
        step = np.zeros(oracle.n)
        step[k] = h
        fp, gradp, gp, Jp = (np.copy(v) for v in oracle.first_order(x + step))
        fm, gradm, gm, Jm = (np.copy(v) for v in oracle.first_order(x - step))
        fd_grad[k] = (fp - fm) / (2 * h)
        fd_J[:, k] = (gp - gm) / (2 * h)
        fd_H[:, k] = ((gradp + Jp.T @ lam) - (gradm + Jm.T @ lam)) / (2 * h)
    np.testing.assert_allclose(grad, fd_grad, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(J, fd_J, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(H, fd_H, rtol=1e-4, atol=1e-4 * max(1.0, np.abs(H).max()))


@pytest.mark.parametrize("collision", [False, True])
def test_row_order_does_not_decide_the_solution(collision):
    """The program's rows in three random orders (blocks and rows within them mixed): the
    same solution, from the same start, each time."""
    oracle, x0, bounds = _reach_inputs(collision, 23)
    reference = sqp(oracle, x0, bounds, SQPOptions())
    assert reference.status == "Solve_Succeeded"
    for seed in range(3):
        order = np.random.default_rng(seed).permutation(oracle.m)
        permuted = _Permuted(oracle, order)
        run = sqp(permuted, x0, permuted.bounds(bounds), SQPOptions())
        assert run.status == "Solve_Succeeded", seed
        np.testing.assert_allclose(run.x, reference.x, atol=1e-6)
        np.testing.assert_allclose(run.lam_g, reference.lam_g[order], atol=1e-5)


class _Counting:
    """An oracle that counts its Hessian evaluations."""

    def __init__(self, oracle: Oracle) -> None:
        self.oracle, self.n, self.m, self.hessians = oracle, oracle.n, oracle.m, 0

    def first_order(self, x):
        return self.oracle.first_order(x)

    def hessian(self, x, sigma, lam_g):
        self.hessians += 1
        return self.oracle.hessian(x, sigma, lam_g)


@pytest.mark.parametrize("collision", [False, True])
def test_the_hessian_kept_between_evaluations_finds_the_same_solution(collision, monkeypatch):
    """With ∇²L evaluated at one accepted step of HESSIAN_EVERY (carried by a damped BFGS
    update at the others), a run evaluates it at most once per HESSIAN_EVERY accepted steps,
    fewer times than the run that evaluates it at every step, and ends where that run ends."""
    oracle, x0, bounds = _reach_inputs(collision, 29)
    accepted = [0]
    original = core._try_step

    def counted(*args):
        step = original(*args)
        accepted[0] += step is not None
        return step

    monkeypatch.setattr(core, "_try_step", counted)
    kept = _Counting(oracle)
    run = sqp(kept, x0, bounds, SQPOptions())
    steps, accepted[0] = accepted[0], 0
    monkeypatch.setattr(core, "HESSIAN_EVERY", 1)
    every = _Counting(oracle)
    reference = sqp(every, x0, bounds, SQPOptions())
    assert run.status == reference.status == "Solve_Succeeded"
    assert every.hessians >= accepted[0]  # the first iterate's, then one per accepted step
    assert kept.hessians <= -(-steps // core.HESSIAN_EVERY) + 1
    assert kept.hessians < every.hessians
    np.testing.assert_allclose(run.x, reference.x, atol=1e-6)
    np.testing.assert_allclose(run.lam_g, reference.lam_g, atol=1e-5)


def test_a_start_at_the_solution_with_its_multipliers_takes_no_iteration(free_problems):
    problem = _with(free_problems[3], method="sqp")
    first = solve(problem)
    assert first.success and first.iterations > 3
    again = solve(problem, start=first)
    assert again.success and again.method == "sqp"
    assert again.iterations <= 1


def test_auto_falls_back_to_ipopt_from_the_same_start(free_problems, monkeypatch):
    def failing(oracle, x0, bounds, options, **kwargs):
        n, m = oracle.n, oracle.m
        return SQPRun(
            x0, 0.0, np.zeros(m), np.zeros(n), "Maximum_Iterations_Exceeded", 7, 7, None, 0.0
        )

    monkeypatch.setattr(runs_module, "sqp", failing)
    result = solve(_with(free_problems[0], method="auto"))
    assert result.success and result.method == "ipopt"
    assert result.iterations_by_method["sqp"] == 7
    assert result.iterations == 7 + result.iterations_by_method["ipopt"]
    only_sqp = solve(_with(free_problems[0], method="sqp"))
    assert not only_sqp.success and "the SQP did not converge" in only_sqp.message


def test_solver_names_are_checked(monkeypatch):
    with pytest.raises(InputError, match=r"^options.solver.method: unknown solver 'snopt'"):
        SolverOptions(method="snopt")
    with pytest.raises(InputError, match=r"^options.solver.qp: unknown QP solver 'osqp'"):
        SolverOptions(qp="osqp")
    monkeypatch.setenv("POSTUREGEN_SOLVER", "fast")
    with pytest.raises(InputError, match=r"^\$POSTUREGEN_SOLVER: unknown solver 'fast'"):
        SolverOptions().solver_method()
    monkeypatch.setenv("POSTUREGEN_SOLVER", "ipopt")
    assert SolverOptions().solver_method() == "ipopt"
    assert SolverOptions(method="sqp").solver_method() == "sqp"
    assert _solvers("sqp, ipopt") == ["sqp", "ipopt"]
    with pytest.raises(PosturegenError, match="--solver: unknown solver 'snopt'"):
        _solvers("sqp,snopt")


def test_row_order_does_not_decide_a_shipped_climb(monkeypatch, tmp_path):
    """HRP-2's inclined ladder under ``auto``: the SQP sees every stage's rows (blocks, and
    rows within them) in three random orders, and every stage verifies each time. (The
    postures are not the same in every order: a stage's SQP may end at another local
    solution, up to 4 cm away on this climb; the QP's working sets, and so the path, depend
    on the order where the QPs are degenerate.)"""
    from posturegen.climb.scenes import scene
    from posturegen.climb.sequence import run_sequence
    from posturegen.verify import verify_file

    monkeypatch.setenv("POSTUREGEN_SOLVER", "auto")
    original = runs_module.sqp

    def climbed(seed: int) -> list[str]:
        def permuted(oracle, x0, bounds, options, **kwargs):
            order = np.random.default_rng(seed).permutation(oracle.m)
            shuffled = _Permuted(oracle, order)
            if kwargs.get("lam_g0") is not None:
                kwargs["lam_g0"] = kwargs["lam_g0"][order]
            if kwargs.get("duals0") is not None:
                n = oracle.n
                duals = kwargs["duals0"]
                kwargs["duals0"] = np.concatenate([duals[:n], duals[n:][order]])
            run = original(shuffled, x0, shuffled.bounds(bounds), options, **kwargs)
            run.lam_g = run.lam_g[np.argsort(order)]  # the program's order, for the caller
            return run

        monkeypatch.setattr(runs_module, "sqp", permuted)
        out = tmp_path / f"order-{seed}"
        report = run_sequence(scene("ladder-inclined", "hrp2", 1), out)
        assert len(report.stages) == report.planned, (seed, report.stages[-1].result.message)
        for stage in report.stages:
            assert verify_file(out / stage.posture_file).ok, (seed, stage.name)
        return [stage.result.method for stage in report.stages]

    for seed in range(3):
        assert any(method == "sqp" for method in climbed(seed))  # the SQP found stages


def test_an_elastic_step_whose_violation_cannot_fall_stops_raising_the_penalty():
    """A row violated by 1 that the region lets move by 0.02 at most: the elastic QP's step
    cannot cut the linearized violation by 10 %, and ν is raised ELASTIC_RAISES times, not
    up to PENALTY_MAX (each raise an elastic QP; at 1e8 they failed and took seconds)."""
    from posturegen.solver.sqp import core

    qp = QP(
        B=np.eye(2),
        c=np.zeros(2),
        A=np.array([[1.0, 1.0]]),
        lb=np.full(2, -0.01),
        ub=np.full(2, 0.01),
        lbA=np.array([1.0]),
        ubA=np.array([np.inf]),
        equal=np.array([False]),
    )
    run = SQPRun(np.zeros(2), 0.0, np.zeros(1), np.zeros(2), "", 0, 0, None, 0.0)
    sol, penalty = core._elastic(qp, 1.0, SQPOptions(), run)
    assert sol.solved
    np.testing.assert_allclose(sol.d, [0.01, 0.01], atol=1e-8)  # as far as the region goes
    assert run.elastic_qps == core.ELASTIC_RAISES + 1
    assert penalty == 10.0**core.ELASTIC_RAISES


class _NaNBeyond:
    """min (x - 2)² s.t. -10 <= x <= 10 (one row), with f not finite beyond x = 1.5: the
    oracle of a program whose functions fail outside a region."""

    n, m = 1, 1

    def value(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        f = float((x[0] - 2.0) ** 2) if x[0] <= 1.5 else float("nan")
        return f, x.copy()

    def first_order(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        f, g = self.value(x)
        return f, np.array([2.0 * (x[0] - 2.0)]), g, np.ones((1, 1))

    def hessian(self, x: np.ndarray, sigma: float, lam_g: np.ndarray) -> np.ndarray:
        return np.array([[2.0 * sigma]])


def test_a_trial_point_where_the_functions_are_not_finite_is_rejected():
    """The step to x = 2 meets f = NaN: rejected (a NaN ratio once passed `ratio < ETA`), the
    run ends at a finite point."""
    bounds = Bounds(
        np.array([-10.0]), np.array([10.0]), np.array([-10.0]), np.array([10.0]), np.ones(1)
    )
    run = sqp(_NaNBeyond(), np.zeros(1), bounds, SQPOptions(max_iter=50))  # type: ignore[arg-type]
    assert np.isfinite(run.f) and run.x[0] <= 1.5
    assert run.x[0] > 1.0  # it moved towards the optimum as far as the functions allow


def _torque_rows(problem) -> slice:
    return Program.of(problem).compile().g_index["torque_limits"]


@pytest.mark.parametrize("bound", [False, True])
def test_torque_continuation_runs_only_when_the_limits_bound_the_sqp(
    free_problems, monkeypatch, bound
):
    """A failed SQP whose torque rows bound none of its steps is not run again with the limits
    relaxed (it would take the same steps); one whose torque rows bound is."""
    problem = _with(free_problems[1], method="sqp")
    rows = _torque_rows(problem)
    real, scales = runs_module.sqp, []

    def failing(oracle, x0, bounds, options, **kwargs):
        run = real(oracle, x0, bounds, options, **kwargs)
        scales.append(float(bounds.ubg[rows].max()))
        run.status = "Infeasible_Problem_Detected"
        run.rows_bound = np.zeros_like(run.rows_bound)
        run.rows_bound[rows.start] = bound
        return run

    monkeypatch.setattr(runs_module, "sqp", failing)
    result = solve(problem)
    assert not result.success
    assert scales == ([1.0, 2.0] if bound else [1.0])


def test_the_sqp_marks_the_rows_that_bound_its_steps(free_problems, monkeypatch):
    """rows_bound holds every row with a multiplier at the solution; the torque rows when the
    limits are tight enough to bind; at ten times Talos' own limits, only when a QP of the
    run had no solution (a row within reach of its region may be why)."""
    real, seen = runs_module.sqp, []

    def kept(*args, **kwargs):
        seen.append(real(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(runs_module, "sqp", kept)
    problem = _with(free_problems[1], method="sqp")
    rows = _torque_rows(problem)
    for scale, binds in ((10.0, False), (0.05, True)):
        seen.clear()
        result = solve(dataclasses.replace(problem, torque_limit_scale=scale))
        assert result.success == (not binds)
        assert np.all(seen[-1].rows_bound[seen[-1].lam_g != 0])
        first = seen[0]
        if binds:
            assert first.rows_bound[rows].any()
        else:
            infeasible_qps = first.relaxed_qps + first.elastic_qps
            assert not first.rows_bound[rows].any() or infeasible_qps > 0


def test_rows_out_of_reach_of_the_region_cannot_be_why_a_qp_has_no_solution():
    """_reachable: a row that every d of the box satisfies is not marked; a row the box's
    corners cross is, and so is one already violated at d = 0."""
    A = np.array([[1.0, 1.0], [1.0, -1.0], [0.0, 1.0]])
    box = np.full(2, 0.5)
    qp = QP(
        np.eye(2),
        np.zeros(2),
        A,
        -box,
        box,
        np.array([-2.0, -0.5, 0.2]),  # row 0: A d in [-1, 1] inside [-2, 2]
        np.array([2.0, 0.5, 1.0]),  # row 1: [-1, 1] crosses ±0.5; row 2: needs d₁ >= 0.2
        np.zeros(3, dtype=bool),
    )
    np.testing.assert_array_equal(_reachable(qp), [False, True, True])


@pytest.mark.parametrize("backend", ["daqp", "proxsuite"])
def test_theta_max_is_the_largest_share_of_the_violations_the_region_allows(backend):
    """Rows d₀ >= 1 and d₁ <= -0.5 violated at d = 0, an equality d₂ = 0.4 (violated), a row
    d₀ - d₁ <= 0.1 that holds at d = 0, the region |d| <= 0.2. At θ the violated rows ask
    d₀ >= θ, d₁ <= -θ/2, d₂ = 0.4 θ, so 1.5 θ <= d₀ - d₁ <= 0.1: θ = 1/15 (the region alone
    allows 0.2, the equality 0.5). The relaxed step asks half of it and meets it."""
    inf = np.inf
    qp = QP(
        np.eye(3),
        np.zeros(3),
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, -1.0, 0.0]]),
        np.full(3, -0.2),
        np.full(3, 0.2),
        np.array([1.0, -inf, 0.4, -inf]),
        np.array([inf, -0.5, 0.4, 0.1]),
        np.array([False, False, True, False]),
    )
    options = SQPOptions(qp=backend)
    assert registry.solve(qp, backend).status == "infeasible"
    assert _theta_max(qp, options, qp.lbA > 0, qp.ubA < 0) == pytest.approx(1 / 15, abs=1e-7)
    wider = dataclasses.replace(qp, ubA=np.array([inf, -0.5, 0.4, 10.0]))
    # the region's bound
    assert _theta_max(wider, options, wider.lbA > 0, wider.ubA < 0) == pytest.approx(0.2, abs=1e-7)
    run = SQPRun(np.zeros(3), 0.0, np.zeros(4), np.zeros(3), "", 0, 0, None, 0.0)
    run.rows_bound = np.zeros(4, dtype=bool)
    sol = _relaxed(qp, options, run)
    theta = 0.5 / 15
    assert sol.solved
    assert sol.d[0] >= theta - 1e-8 and sol.d[1] <= -theta / 2 + 1e-8
    assert sol.d[2] == pytest.approx(0.4 * theta, abs=1e-8)
    assert sol.d[0] - sol.d[1] <= 0.1 + 1e-8
    assert run.relaxed_qps == 2  # the θ-max QP and the step's: no ladder


def test_a_run_settles_after_feasible_iterates_whose_cost_no_longer_changes():
    """_Flat: FLAT_ITERATIONS feasible iterates in a row whose cost moves by less than
    FLAT_CHANGE × max(1, |f|) settle; an infeasible one starts the count again; a cost that
    still falls by 1e-4 an iterate never settles."""
    bounds = Bounds(np.zeros(1), np.ones(1), np.zeros(1), np.zeros(1), np.ones(1))
    options = SQPOptions()

    def at(f: float, g: float) -> Iterate:
        return Iterate.of(np.zeros(1), f, np.zeros(1), np.array([g]), np.zeros((1, 1)), bounds)

    flat = _Flat()
    costs = 2.0 - 1e-8 * np.arange(3 * core.FLAT_ITERATIONS)
    settled = [flat.settled(at(f, 0.0 if i != 4 else 1e-3), options) for i, f in enumerate(costs)]
    assert settled.index(True) == 4 + core.FLAT_ITERATIONS  # the count restarted after #4
    falling = _Flat()
    assert not any(falling.settled(at(2.0 - 1e-4 * i, 0.0), options) for i in range(50))


def test_the_model_counts_no_linearized_residue_below_the_qps_tolerance():
    """At a feasible point, a step whose linearized rows miss their bounds by the QP's own
    tolerance (1e-10 a row) still promises its cost's decrease, whatever ν; a row missed by
    more than LINEAR_TOL is charged ν per unit."""
    bounds = Bounds(
        np.full(2, -1.0), np.full(2, 1.0), np.zeros(3), np.zeros(3), np.ones(2)
    )  # g(x) = 0 on three equality rows
    grad = np.array([1.0, 0.0])
    J = np.zeros((3, 2))
    J[0, 1] = 1.0  # the rows move with x₁ only, the cost with x₀
    it = Iterate.of(np.zeros(2), 0.0, grad, np.zeros(3), J, bounds)
    Bs = np.eye(2)
    d = np.array([-1e-3, 5e-10])  # row 0 off by 5e-10: the QP's residue
    promised = _Promise.of(it, Bs, d, bounds).reduction(it, 1e8)
    assert promised == pytest.approx(1e-3 - 0.5e-6, rel=1e-9)
    d[1] = 10 * LINEAR_TOL
    charged = _Promise.of(it, Bs, d, bounds).reduction(it, 1e8)
    assert charged == pytest.approx(1e-3 - 0.5e-6 - 1e8 * 10 * LINEAR_TOL, rel=1e-6)


def test_a_failed_auto_call_is_made_again_with_ipopt_alone(free_problems, monkeypatch):
    """An ``auto`` call is the SQP's call; when it fails (here: its runs stopped at 2
    iterations), IPOPT's call from the same start, as IPOPT alone makes it: its verified
    posture, counted with every run of both calls."""
    original_sqp = runs_module._sqp

    def short_sqp(start):
        options = dataclasses.replace(start.program.solver_options, max_iter=2)
        return original_sqp(
            dataclasses.replace(start, program=start.program.but(solver_options=options))
        )

    monkeypatch.setattr(runs_module, "_sqp", short_sqp)
    result = solve(_with(free_problems[0], method="auto"))
    alone = solve(_with(free_problems[0], method="ipopt"))
    assert result.success and result.method == "ipopt", result.message
    assert result.iterations_by_method["sqp"] >= 2
    assert result.iterations_by_method["ipopt"] == alone.iterations, result.iterations_by_method
    assert result.iterations == sum(result.iterations_by_method.values())
    np.testing.assert_array_equal(result.q, alone.q)


def test_an_sqp_run_from_a_start_the_call_already_ran_is_not_made_again(free_problems):
    """Within one call (one Budget), a second SQP run from the same start (or within
    REPLAY_TOL of it) is the first run replayed: the same solution, no iteration; a start
    farther away, other bounds or no call at all run the SQP."""
    program = Program.of(_with(free_problems[2], method="sqp"))
    x0 = program.numeric(program.compile())[0]
    token = runs_module.BUDGET.set(runs_module.Budget(None))
    try:
        first = runs_module.run_nlp(program, x0)[-1]
        again = runs_module.run_nlp(program, x0 + 0.1 * runs_module.REPLAY_TOL)[-1]
        moved = runs_module.run_nlp(program, x0 + 1e-3)[-1]
        looser = program.but(torque_limit_scale=2.0)
        relaxed = runs_module.run_nlp(looser, x0)[-1]
    finally:
        runs_module.BUDGET.reset(token)
    outside = runs_module.run_nlp(program, x0)[-1]
    assert first.ok and first.iterations > 3 and not first.replayed
    assert again.replayed and again.iterations == 0 and np.array_equal(again.x, first.x)
    for run in (moved, relaxed, outside):
        assert not run.replayed and run.iterations > 0


def test_ipopts_own_options_do_not_make_an_sqp_run_new(free_problems):
    """Each solver-option variant of a structure is a solver object of its own; the SQP reads
    none of IPOPT's options (its barrier, its warm start): a run from the same start under
    other IPOPT options is replayed, under another time limit or QP backend it is not (the
    active-set loop's cold retry and its continuations rebuilt the same program with other
    IPOPT options and ran the same failing 29-iteration SQP run again)."""
    program = Program.of(_with(free_problems[2], method="sqp"))
    x0 = program.numeric(program.compile())[0]
    options = program.solver_options

    def variant(**changes):
        return program.but(solver_options=dataclasses.replace(options, **changes))

    ipopt_only = variant(mu_init=0.5, warm_start=not options.warm_start)
    assert ipopt_only.compile() is not program.compile()
    token = runs_module.BUDGET.set(runs_module.Budget(None))
    try:
        first = runs_module.run_nlp(program, x0)[-1]
        again = runs_module.run_nlp(ipopt_only, x0)[-1]
        timed = runs_module.run_nlp(variant(max_cpu_time=options.max_cpu_time / 2), x0)[-1]
        other_qp = runs_module.run_nlp(variant(qp="proxsuite"), x0)[-1]
    finally:
        runs_module.BUDGET.reset(token)
    assert first.ok and first.iterations > 3 and not first.replayed
    assert again.replayed and again.iterations == 0 and np.array_equal(again.x, first.x)
    for run in (timed, other_qp):
        assert not run.replayed and run.iterations > 0


def test_a_penalty_steered_up_far_from_feasibility_comes_down_at_a_feasible_posture(monkeypatch):
    """A varied stance (seeds 1, #115) whose second round's penalty was steered to 5.6e4 while
    its rows were 2 cm from holding: at the feasible postures after it, that ν weighed each
    step's 1e-8 curvature violations against its cost and held the region at 7.6e-4 for 120
    iterations (the SQP spent its 150, IPOPT took 97 more). With ν brought down to
    PENALTY_OVER_MULTIPLIERS × ‖λ‖∞ after each accepted step the SQP verifies it alone, in
    fewer than 100 iterations; kept where the steering left it, it does not."""
    from posturegen.bench.reach import stances_family
    from posturegen.solver import solve as solve_module

    stance = list(stances_family(117, 1))[116]
    stance = dataclasses.replace(
        stance, solver_options=dataclasses.replace(stance.solver_options, method="sqp")
    )
    solve_module._LEARNED.clear()
    result = solve(stance)
    assert result.success, result.message
    assert result.iterations_by_method == {"sqp": result.iterations} and result.iterations < 100
    monkeypatch.setattr(core, "PENALTY_OVER_MULTIPLIERS", np.inf)  # both loops read it
    solve_module._LEARNED.clear()
    kept = solve(stance)
    assert not kept.success or kept.iterations >= 150
