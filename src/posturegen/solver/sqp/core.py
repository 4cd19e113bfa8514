"""An SQP for posture programs: Fletcher's Sℓ1QP (a trust region in scaled variables, the
ℓ1 merit f + ν‖viol(g)‖₁, elastic QPs where the linearization is inconsistent, a
second-order correction of a rejected step), on a dense QP backend warm-started from the
previous working set.

Each iteration: B = ∇²L made positive definite (:mod:`.hessian`), evaluated at every
HESSIAN_EVERY-th accepted step and carried by a damped BFGS update in between (:mod:`.model`;
∇f and J are always the iterate's); the QP

    min ½ dᵀBd + ∇fᵀd  s.t.  lbg <= g + J d <= ubg,  lbx <= x + d <= ubx,  |d_i| <= Δ s_i

solved in the scaled variables d̃ = d / s (its elastic form when it has no solution); the
step is taken when the merit's actual reduction is at least ETA of the model's; else the
second-order correction (the same QP with its rows shifted by g(x + d) - g - J d) is tried,
then the region shrinks. When the QP has no solution in the region, its violated rows ask for
a fraction θ of their correction (Vardi's relaxation: half the largest θ that has one, found
by one QP, :func:`_theta_max`); the elastic QP is the last resort. ν only grows, as the steps
need it (:func:`_steered`), up to PENALTY_MAX.
Converged when the constraints hold to ``tol_primal`` and ∇f + Jᵀλ_g + λ_x to ``tol_dual``
(relative to max(1, ‖∇f‖∞))."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..qp import registry
from ..qp.base import QP, QPSolution
from .elastic import solve_elastic
from .iterate import Bounds, Iterate, max_abs
from .model import Model, corrected, model_at, relinearized
from .oracle import Oracle

ETA = 1e-4  # a step is taken when the merit decreases by this fraction of the model's
# a rejected step's region: this fraction of the smaller of the region and the step (0.25
# until 2026-12-05: 4 never-seen families x 2 seeds x 49 problems in-process, 7864 -> 7393
# SQP iterations, the same 388 verified; 0.35 and 0.7: 7744 and 7906, 0.7 verified 384, these
# two measured with a scan whose distances differed in the last bit)
SHRINK = 0.5
RADIUS_MAX = 4.0  # [scaled units] the trust region's largest radius
PENALTY_MAX = 1e8
# after each accepted step ν comes down to this many times the step's largest multiplier
# ‖λ‖∞ (never below the first ν): the ℓ1 merit is exact for ν > ‖λ*‖∞, and a ν steered up
# where the rows were far from holding (5.6e4 on a Talos stance) weighed the 1e-8 violations
# that each step's curvature makes against its cost: ratios of 0.2-0.6 kept the region at
# 7.6e-4 for 120 iterations at a feasible posture. A step that needs more gets it from the
# steering (:func:`_steered`). Python core, in-process, 100 problems each, both codes in one
# session: SQP iterations stances seeds 0 / 1 / 2: 1507 / 1695 / 1734 -> 1496 / 1533 / 1633
# (seed 1's one IPOPT call, 40 iterations, gone), near-body seed 2: 2440 -> 2341, box seed 1
# 1970 -> 1907, reach-balance collision and free seed 1: 1243 -> 1233, 829 -> 830; the same
# postures verified; only when the iterate was feasible to 1e-6 or 1e-4: fewer than these
PENALTY_OVER_MULTIPLIERS = 2.0
# iterations without the constraints' ℓ1 violation falling by 1 % below its best: the run
# stops, infeasible (a squat whose thighs cannot part by the margin ran 1000 iterations of
# relaxed steps that kept the violation where it was)
STALL_ITERATIONS = 30
SUCCEEDED = "Solve_Succeeded"  # IPOPT's names: the orchestrator reads both solvers alike
ACCEPTABLE = "Solved_To_Acceptable_Level"
UNFINISHED = "Maximum_Iterations_Exceeded"  # a run's status until it ends otherwise
# the Hessian of the Lagrangian (its evaluation and its convexification: 0.5 of a Talos
# collision iteration's 1.1 ms, the generated Hessian alone 0.27 ms, cache-cold) is evaluated at
# one accepted step of this many; at the others the last one is carried by a damped BFGS update
# along the step (:func:`.model.relinearized`). Never-seen families, 49 problems each, seeds
# 104731 and 104733, in-process, both codes in one run, median call: reach-balance-collision
# 15.5 -> 13.4 and 15.5 -> 13.1 ms, near-body 20.4 -> 18.4 and 24.8 -> 21.9, stances 20.4 ->
# 18.5 and 19.7 -> 18.4, box 16.9 -> 15.0 and 18.6 -> 16.1, reach-balance-free 5.2 -> 4.4 and
# 5.6 -> 4.8; the slowest calls 108 -> 44, 149 -> 111, 131 -> 26 ms (reach, near-body, box);
# SQP iterations +10-30 %; verified the same but one stance of seed 104731 (its call's budget
# spent), the stances of seeds 0-2 (150 each) 147, 146, 145 -> 147, 146, 146. The Hessian kept
# without the update: a few percent faster on the reaches, but a Talos stance on one foot after
# a non-inclusive step (tests/test_contacts.py) ran two runs of 29 and 44 iterations until
# their regions were nothing, where the update took 11 (the Hessian at every step 5). Kept
# for 2, 5 or 7 steps instead of 3 (without the update): within the machine's noise
HESSIAN_EVERY = 4
# accepted steps in a row at feasible iterates whose cost changes by less than FLAT_CHANGE ×
# max(1, |f|): the run stops there, acceptable (a Talos stance crawled 100 iterations at a
# feasible point, each lowering its cost by 1e-8 along a direction of almost no curvature
# with steps of 1e-5; 117 -> 18 iterations). The posture is re-checked as any other
FLAT_ITERATIONS = 10
FLAT_CHANGE = 1e-6


@dataclass(frozen=True)
class SQPOptions:
    """The SQP's settings."""

    max_iter: int = 100
    max_time_s: float = 30.0  # [s] wall time of a run (SolverOptions.max_cpu_time)
    tol_primal: float = 1e-9  # [m, N·m, N] the largest violation of a constraint
    tol_dual: float = 1e-6  # ‖∇L‖∞ relative to max(1, ‖∇f‖∞)
    radius: float = 1.0  # [scaled units] the first trust region
    radius_min: float = 1e-10
    penalty: float = 1.0  # ν to start from
    qp: str | None = None  # the QP backend (None: the first available)


@dataclass
class SQPRun:
    """What one SQP run found."""

    x: np.ndarray  # (n,)
    f: float
    lam_g: np.ndarray  # (m,)
    lam_x: np.ndarray  # (n,)
    status: str
    iterations: int
    qp_iterations: int
    duals: np.ndarray | None  # (n + m,) the last QP's multipliers: its working set
    wall_s: float
    modified_hessians: int = 0
    relaxed_qps: int = 0
    elastic_qps: int = 0
    history: list[tuple[float, float, float]] = field(default_factory=list)  # f, viol, Δ
    # (m,) the rows that bound the run: violated at an iterate, with a multiplier in a step's
    # QP, or within reach of a region whose QP had no solution; a bound of the other rows can
    # be relaxed without changing any step
    rows_bound: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))


@dataclass
class _Stall:
    """The best ℓ1 violation so far and the iterations since it last fell by 1 %."""

    best: float
    since: int = 0

    def stuck(self, violation: float, options: SQPOptions) -> bool:
        """Count this iteration; True after STALL_ITERATIONS without progress while the
        constraints do not hold."""
        if violation < 0.99 * self.best or violation <= options.tol_primal:
            self.best, self.since = min(self.best, violation), 0
            return False
        self.since += 1
        return self.since >= STALL_ITERATIONS


@dataclass
class _Flat:
    """The costs of the last accepted iterates, feasible all (cleared at an infeasible one)."""

    costs: list[float] = field(default_factory=list)

    def settled(self, it: Iterate, options: SQPOptions) -> bool:
        """Count an accepted iterate; True after FLAT_ITERATIONS feasible ones whose cost
        changed by at most FLAT_CHANGE × max(1, |f|)."""
        if it.worst > options.tol_primal:
            self.costs.clear()
            return False
        self.costs.append(it.f)
        last = self.costs[-FLAT_ITERATIONS:]
        change = max(last) - min(last)
        return len(last) == FLAT_ITERATIONS and change <= FLAT_CHANGE * max(1.0, abs(it.f))


def sqp(
    oracle: Oracle,
    x0: np.ndarray,
    bounds: Bounds,
    options: SQPOptions,
    lam_g0: np.ndarray | None = None,
    lam_x0: np.ndarray | None = None,
    duals0: np.ndarray | None = None,
) -> SQPRun:
    """Solve min f s.t. the bounds from x0 (with multipliers and a working set when given)."""
    t0 = time.perf_counter()
    run, it = _first(oracle, x0, bounds, lam_g0, lam_x0, duals0)
    lam_g, lam_x, radius, penalty = run.lam_g, run.lam_x, options.radius, options.penalty
    # the iterate's QP model (the same arrays for each of its QPs: the QP backend keeps its
    # factorization for them); kept: the accepted steps since its Hessian was evaluated
    scaled: Model | None = None
    kept, stall, flat = 0, _Stall(it.l1), _Flat()
    for _ in range(options.max_iter):
        run.rows_bound |= it.viol > 0
        stop = _stop(it, lam_g, lam_x, bounds, options, stall, t0)
        if stop is not None:
            run.status = stop
            break
        if scaled is None:
            scaled, kept = model_at(oracle, it, lam_g, lam_x, bounds), 0
            run.modified_hessians += scaled.modified
        run.iterations += 1
        qp = _qp(it, scaled, bounds, radius, run.duals)
        sol, penalty, promise = _step(qp, it, bounds, penalty, options, run, scaled)
        if promise is None:  # neither the QP nor its elastic form had a solution
            run.status = "Error_In_Step_Computation"
            break
        d_size = float(np.max(np.abs(sol.d) / bounds.scale, initial=0.0))
        if d_size < 1e-12:  # the QP stays where it is: its multipliers are the news
            lam_g, lam_x, run.status = _standing(sol, qp, it, bounds, options)
            if run.status == SUCCEEDED or not kept:
                break
            scaled, run.status = None, UNFINISHED  # stalled on a kept Hessian: evaluate it
            continue
        run.history.append((it.f, it.worst, radius))
        step = _try_step(oracle, it, sol, qp, bounds, penalty, options, promise)
        if step is None:  # rejected: a smaller region
            radius, fresh = _shrunk(radius, d_size, kept, options)
            if radius < options.radius_min:
                run.status = _stalled(it, options)
                break
            scaled = None if fresh else scaled
            continue
        previous, (it, ratio) = it, step
        lam_g, lam_x = sol.lam_rows, _own_bound_multipliers(sol, qp, it, bounds)
        penalty, kept = _lowered(penalty, lam_g, options), kept + 1
        scaled = relinearized(scaled, previous, it, lam_g, bounds) if kept < HESSIAN_EVERY else None
        if flat.settled(it, options) and not _converged(it, lam_g, lam_x, bounds, options):
            run.status = ACCEPTABLE
            break
        if ratio > 0.75 and d_size >= 0.99 * radius:
            radius = min(2.0 * radius, RADIUS_MAX)
    else:
        run.status = SUCCEEDED if _converged(it, lam_g, lam_x, bounds, options) else run.status
    return _finished(run, it, lam_g, lam_x, t0)


def _lowered(penalty: float, lam_g: np.ndarray, options: SQPOptions) -> float:
    """ν after an accepted step with row multipliers ``lam_g`` (m,): at most
    PENALTY_OVER_MULTIPLIERS × ‖λ‖∞, at least ``options.penalty``."""
    return max(options.penalty, min(penalty, PENALTY_OVER_MULTIPLIERS * max_abs(lam_g)))


def _shrunk(radius: float, d_size: float, kept: int, options: SQPOptions) -> tuple[float, bool]:
    """The region after a step of size ``d_size`` [scaled] was rejected, SHRINK of the smaller
    of both, and whether the model's Hessian is to be evaluated: a region below
    ``radius_min`` ends the run, but not on a Hessian kept for ``kept`` steps (it is evaluated
    and the region starts again from ``options.radius``)."""
    radius = SHRINK * min(radius, d_size)
    if radius < options.radius_min and kept:
        return options.radius, True
    return radius, False


def _finished(run: SQPRun, it: Iterate, lam_g: np.ndarray, lam_x: np.ndarray, t0: float) -> SQPRun:
    """``run`` ended at ``it`` with its multipliers and its wall time since ``t0``."""
    run.x, run.f, run.lam_g, run.lam_x = it.x, it.f, lam_g, lam_x
    run.wall_s = time.perf_counter() - t0
    return run


def _stop(
    it: Iterate,
    lam_g: np.ndarray,
    lam_x: np.ndarray,
    bounds: Bounds,
    options: SQPOptions,
    stall: _Stall,
    t0: float,
) -> str | None:
    """Why the run ends before this iteration (converged, out of time, stalled), or None."""
    if _converged(it, lam_g, lam_x, bounds, options):
        return SUCCEEDED
    if time.perf_counter() - t0 > options.max_time_s:
        return "Maximum_CpuTime_Exceeded"
    if stall.stuck(it.l1, options):
        return "Infeasible_Problem_Detected"
    return None


def _first(
    oracle: Oracle,
    x0: np.ndarray,
    bounds: Bounds,
    lam_g0: np.ndarray | None,
    lam_x0: np.ndarray | None,
    duals0: np.ndarray | None,
) -> tuple[SQPRun, Iterate]:
    """The run's record and its first iterate (x0 inside its bounds)."""
    x = np.clip(x0, bounds.lbx, bounds.ubx)
    lam_g = np.zeros(oracle.m) if lam_g0 is None else np.array(lam_g0, dtype=float)
    lam_x = np.zeros(oracle.n) if lam_x0 is None else np.array(lam_x0, dtype=float)
    run = SQPRun(x, 0.0, lam_g, lam_x, UNFINISHED, 0, 0, duals0, 0.0)
    run.rows_bound = np.zeros(oracle.m, dtype=bool)
    return run, _at(oracle, x, bounds)


def _step(
    qp: QP,
    it: Iterate,
    bounds: Bounds,
    penalty: float,
    options: SQPOptions,
    run: SQPRun,
    model: Model,
) -> tuple[QPSolution, float, _Promise | None]:
    """The QP's step (relaxed when its rows cannot hold in the region, elastic as the last
    resort), the penalty it needs and what its model promises (None: no step); its
    multipliers the program's (model.corrected)."""
    sol = _relaxed(qp, options, run)
    if sol.solved:
        sol = _unscaled(sol, bounds.scale)
        run.duals = sol.duals
        promise = _Promise.of(it, qp.B, sol.d, bounds)
        penalty = _steered(it, promise, penalty)
    else:
        sol, penalty = _elastic(qp, penalty, options, run)
        sol = _unscaled(sol, bounds.scale)
        promise = _Promise.of(it, qp.B, sol.d, bounds) if sol.solved else None
    run.qp_iterations += sol.iterations
    if sol.solved:
        sol = corrected(sol, model, qp.equal, bounds.scale)
        run.rows_bound |= sol.lam_rows != 0
    return sol, penalty, promise


def _converged(
    it: Iterate, lam_g: np.ndarray, lam_x: np.ndarray, bounds: Bounds, options: SQPOptions
) -> bool:
    """Primal feasibility, stationarity of the Lagrangian, and multipliers of the right sign
    only at rows at their bounds (complementarity, to tol_dual)."""
    if it.worst > options.tol_primal:
        return False
    r = it.grad + it.J.T @ lam_g + lam_x
    scale = max(1.0, max_abs(it.grad))
    if max_abs(r) > options.tol_dual * scale:
        return False
    # a multiplier > 0 needs its row at its upper bound, < 0 at its lower one
    gap = np.where(lam_g > 0, bounds.ubg - it.g, it.g - bounds.lbg)
    gap = np.where(np.isfinite(gap), gap, 1e3)
    return max_abs(lam_g * gap) <= options.tol_dual * scale


def _qp(
    it: Iterate,
    scaled: Model,
    bounds: Bounds,
    radius: float,
    duals: np.ndarray | None,
) -> QP:
    """The QP at ``it`` in the region of ``radius``, in the scaled variables d̃ = d / s:
    ``scaled`` (B̃ = S B S, c̃ = S ∇f, Ã = J S), the bounds divided by s (the rows' are
    unchanged)."""
    s = bounds.scale
    return QP(
        B=scaled.B,
        c=scaled.c,
        A=scaled.A,
        lb=np.maximum((bounds.lbx - it.x) / s, -radius),
        ub=np.minimum((bounds.ubx - it.x) / s, radius),
        lbA=bounds.lbg - it.g,
        ubA=bounds.ubg - it.g,
        equal=bounds.equal,
        dual_start=duals,
    )


def _unscaled(sol: QPSolution, scale: np.ndarray) -> QPSolution:
    """A scaled QP's solution in the variables' units: d = S d̃, λ_d = S⁻¹ λ̃_d (the rows'
    multipliers are the same)."""
    return QPSolution(
        sol.status, sol.d * scale, sol.lam_bounds / scale, sol.lam_rows, sol.iterations
    )


def _curvature(Bs: np.ndarray, d: np.ndarray, scale: np.ndarray) -> float:
    """½ dᵀBd from the scaled B̃ = S B S."""
    ds = d / scale
    return 0.5 * float(ds @ Bs @ ds)


# the fractions θ of the violated rows' linearized correction tried when the QP has no
# solution (Vardi's relaxation; at θ = 0, d = 0 is feasible), after THETA_SHARE of the largest
# θ that has one (:func:`_theta_max`) or where that QP fails. Against this ladder alone (4
# families × 2 seeds × 49 never-seen problems, in-process): 380 -> 385 verified, 7924 ->
# 7537 SQP iterations, near-body's slowest calls 302 / 294 -> 95 / 184 ms (box's 1317 ->
# 1476); a share of 0.3: 385 and 8056, 0.7: 386 and 7480 (both with an earlier θ-max QP),
# 0.99 (the largest θ): more iterations than the ladder on reach-balance
THETAS = (0.5, 0.25, 0.1, 0.03, 0.01, 0.0)
THETA_SHARE = 0.5
# the θ-max QP's weight of θ against ½‖d̃‖²: with 1e3 it finds the largest θ of its region's
# (the same θ as 1e6 against 1e-6 ‖d̃‖², to 1e-9, on 216 QPs of 49 box problems, where that
# scaling stopped daqp on 18 and proxsuite then took 13 ms each); 1 trades θ for a shorter d
THETA_WEIGHT = 1e3


def _relaxed(qp: QP, options: SQPOptions, run: SQPRun) -> QPSolution:
    """The QP, or when its rows cannot hold in the region, the QP whose violated rows ask for
    only θ of their correction: THETA_SHARE of the largest θ that has a solution, else the
    first of THETAS that has one. The region's step then reduces the violation by θ, and the
    merit's model says whether that is worth it."""
    sol = registry.solve(qp, options.qp)
    if sol.status != "infeasible":
        return sol
    run.rows_bound |= _reachable(qp)  # any of them may be why it has no solution
    lower, upper = qp.lbA > 0, qp.ubA < 0  # rows violated at d = 0
    run.relaxed_qps += 1
    top = _theta_max(qp, options, lower, upper)
    thetas = THETAS
    if top is not None:
        first = THETA_SHARE * top
        thetas = (first, *(t for t in THETAS if t < first))
    for theta in thetas:
        run.relaxed_qps += 1
        lbA, ubA = qp.lbA.copy(), qp.ubA.copy()
        lbA[lower | qp.equal] *= theta
        ubA[upper] *= theta
        ubA[qp.equal] = lbA[qp.equal]
        relaxed = QP(qp.B, qp.c, qp.A, qp.lb, qp.ub, lbA, ubA, qp.equal, qp.dual_start)
        sol = registry.solve(relaxed, options.qp)
        if sol.status != "infeasible":
            return sol
    return sol


def _theta_max(qp: QP, options: SQPOptions, lower: np.ndarray, upper: np.ndarray) -> float | None:
    """The largest θ in [0, 1] for which the violated rows asking for θ of their correction
    (lbA θ <= A d or A d <= ubA θ) hold with d in the region: the QP over (d, θ)

        min ½ ‖d̃‖² + ½ θ² - W θ  s.t.  the rows, their violated bounds × θ, 0 <= θ <= 1

    (a violated row's other bound kept at its distance, which θ <= 1 allows). None when the
    backend finds none (d = 0, θ = 0 is one; the ladder of THETAS then decides). ``lower``,
    ``upper`` (m,): the rows whose lower (upper) bound d = 0 violates."""
    n = qp.c.size
    violated = np.where(lower, qp.lbA, np.where(upper, qp.ubA, 0.0))  # (m,)
    with np.errstate(invalid="ignore"):  # inf - inf where a row has no other bound
        lbA = np.where(lower, 0.0, np.where(upper, qp.lbA - qp.ubA, qp.lbA))
        ubA = np.where(upper, 0.0, np.where(lower, qp.ubA - qp.lbA, qp.ubA))
    c = np.zeros(n + 1)
    c[n] = -THETA_WEIGHT
    widened = QP(
        B=np.eye(n + 1),
        c=c,
        A=np.hstack([qp.A, -violated[:, None]]),
        lb=np.append(qp.lb, 0.0),
        ub=np.append(qp.ub, 1.0),
        lbA=lbA,
        ubA=ubA,
        equal=qp.equal,
    )
    sol = registry.backend(options.qp).solve(widened)  # no fallback: the ladder is one
    return float(np.clip(sol.d[n], 0.0, 1.0)) if sol.solved else None


def _reachable(qp: QP) -> np.ndarray:
    """(m,) the rows whose bounds some d of the region's box meets (lb <= d <= ub): the
    others hold for every d in it, and a QP without a solution has it whatever their bounds."""
    low = np.minimum(qp.A * qp.lb, qp.A * qp.ub).sum(axis=1)  # min of A d over the box
    high = np.maximum(qp.A * qp.lb, qp.A * qp.ub).sum(axis=1)
    return (low <= qp.lbA) | (high >= qp.ubA)


# ν ×10 at most this many times within one step's elastic QPs: a linearization whose violation
# cannot fall keeps asking for more (Talos' squat whose thighs cannot part by 1 cm: ν ran to
# PENALTY_MAX, daqp failed on the QP's scaling and proxsuite took seconds per QP, 154 s in one
# run of 28 iterations)
ELASTIC_RAISES = 2


def _elastic(qp: QP, penalty: float, options: SQPOptions, run: SQPRun) -> tuple[QPSolution, float]:
    """The elastic QP's step at ν, ν ×10 (ELASTIC_RAISES times at most) while the step leaves
    the linearized violation above 90 % of the current one (and ν < PENALTY_MAX)."""
    v0 = float(np.sum(np.maximum(np.maximum(qp.lbA, -qp.ubA), 0.0)))
    for raised in range(ELASTIC_RAISES + 1):
        run.elastic_qps += 1
        sol = solve_elastic(qp, penalty, options.qp)
        if not sol.solved or penalty >= PENALTY_MAX or raised == ELASTIC_RAISES:
            break
        Ad = qp.A @ sol.d
        v1 = float(np.sum(np.maximum(np.maximum(qp.lbA - Ad, Ad - qp.ubA), 0.0)))
        if v1 <= 0.9 * v0 or v1 <= 1e-12:
            break
        penalty = min(10.0 * penalty, PENALTY_MAX)
    return sol, penalty


def _steered(it: Iterate, promise: _Promise, penalty: float) -> float:
    """ν large enough that the step's predicted reduction is at least half its reduction of
    the linearized violation, ν ≥ (∇fᵀd + ½dᵀBd) / ((1 - 0.5) Δv) (Nocedal & Wright, 18.36):
    ν follows what the steps need, not the QP's multipliers (a degenerate QP's run to 1e4)."""
    dv = it.l1 - promise.violation
    q = promise.slope + promise.curvature
    if dv > 1e-14 and q > 0:
        penalty = max(penalty, q / (0.5 * dv))
    return min(penalty, PENALTY_MAX)


# [row units] a linearized row within this of its bound holds in the merit's model: the QP
# holds its rows to 1e-10 each (daqp's tolerance), and counted, those residues made a Talos
# touch's model promise less than nothing at a feasible point, its region shrinking to nothing
LINEAR_TOL = 1e-9


def _linearized_violation(it: Iterate, d: np.ndarray, bounds: Bounds) -> float:
    """‖viol(g + J d)‖₁, the rows within LINEAR_TOL of their bounds counted as holding."""
    v = bounds.violation(it.g + it.J @ d)
    return float(np.sum(v[v > LINEAR_TOL]))


@dataclass(frozen=True)
class _Promise:
    """What a step d's model says, made once per step (the penalty and the ratio read it):
    ‖viol(g + J d)‖₁ (:func:`_linearized_violation`), ∇fᵀd and ½dᵀBd."""

    violation: float
    slope: float
    curvature: float

    @classmethod
    def of(cls, it: Iterate, Bs: np.ndarray, d: np.ndarray, bounds: Bounds) -> _Promise:
        """The model of the step d (n,) at ``it``, B̃ = ``Bs`` in the scaled variables."""
        return cls(
            _linearized_violation(it, d, bounds),
            float(it.grad @ d),
            _curvature(Bs, d, bounds.scale),
        )

    def reduction(self, it: Iterate, penalty: float) -> float:
        """ν‖viol(g)‖₁ - (∇fᵀd + ½dᵀBd + ν‖viol(g + J d)‖₁): what the step promises."""
        return penalty * (it.l1 - self.violation) - self.slope - self.curvature


def _try_step(
    oracle: Oracle,
    it: Iterate,
    sol: QPSolution,
    qp: QP,
    bounds: Bounds,
    penalty: float,
    options: SQPOptions,
    promise: _Promise,
) -> tuple[Iterate, float] | None:
    """The next iterate and its ratio actual / predicted reduction (``promise``: the step's
    model), or None when neither the step nor its second-order correction reduces the merit
    enough."""
    pred = promise.reduction(it, penalty)
    merit0 = it.f + penalty * it.l1
    if pred <= 1e-16 * max(1.0, abs(merit0)):
        return None
    # the trial point's first-order values at once: an accepted step (most of them) is the
    # next iterate without evaluating f and g twice
    trial = _at(oracle, np.clip(it.x + sol.d, bounds.lbx, bounds.ubx), bounds)
    ratio = (merit0 - trial.f - penalty * trial.l1) / pred
    if not ratio >= ETA:  # NaN (f or g not finite at the trial point): rejected
        # second-order correction: the rows shifted by their curvature along d
        shift = trial.g - it.g - it.J @ sol.d
        soc = QP(
            qp.B, qp.c, qp.A, qp.lb, qp.ub, qp.lbA - shift, qp.ubA - shift, qp.equal, sol.duals
        )
        corrected = registry.solve(soc, options.qp)
        if not corrected.solved:
            return None
        corrected = _unscaled(corrected, bounds.scale)
        trial = _at(oracle, np.clip(it.x + corrected.d, bounds.lbx, bounds.ubx), bounds)
        ratio = (merit0 - trial.f - penalty * trial.l1) / pred
        if not ratio >= ETA:  # NaN (f or g not finite at the trial point): rejected
            return None
    return trial, ratio


def _at(oracle: Oracle, x: np.ndarray, bounds: Bounds) -> Iterate:
    """The iterate at x: f, ∇f, g, J and the rows' violations."""
    return Iterate.of(x, *oracle.first_order(x), bounds)


def _own_bound_multipliers(sol: QPSolution, qp: QP, it: Iterate, bounds: Bounds) -> np.ndarray:
    """The QP's bound multipliers where the bound is the variable's own (not the region's)."""
    at_lower = (it.x <= bounds.lbx + 1e-12) & (sol.lam_bounds < 0)
    at_upper = (it.x >= bounds.ubx - 1e-12) & (sol.lam_bounds > 0)
    return np.where(at_lower | at_upper, sol.lam_bounds, 0.0)


def _standing(
    sol: QPSolution, qp: QP, it: Iterate, bounds: Bounds, options: SQPOptions
) -> tuple[np.ndarray, np.ndarray, str]:
    """The multipliers (rows, own bounds) of a QP whose step is nothing, and the run's
    status there: converged, else stalled."""
    lam_g, lam_x = sol.lam_rows, _own_bound_multipliers(sol, qp, it, bounds)
    if _converged(it, lam_g, lam_x, bounds, options):
        return lam_g, lam_x, SUCCEEDED
    return lam_g, lam_x, _stalled(it, options)


def _stalled(it: Iterate, options: SQPOptions) -> str:
    """Why the region shrank to nothing: infeasible when the constraints do not hold."""
    if it.worst > options.tol_primal:
        return "Infeasible_Problem_Detected"
    return "Search_Direction_Becomes_Too_Small"
