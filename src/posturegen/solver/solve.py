"""Solving a :class:`~posturegen.solver.problem.Problem`: IPOPT, then an independent re-check.

``solve`` returns a frozen :class:`Result`. ``success`` is True only when IPOPT converged AND
:func:`posturegen.verify.verify_posture` (Pinocchio, not CasADi) accepts the posture.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..collision.active_set import ActiveSet, Scan, placed_blocked
from ..collision.boxes import TIGHTEN_STEP
from ..collision.mesh_check import mesh_clearances
from ..collision.rows import CollisionTerm
from ..collision.separation import separated_start
from ..collision.slots import Capacity
from ..io.posture_file import add_solve_fields, posture_dict
from ..terms.equilibrium import TORQUE_LIMITS
from ..verify import VerifyReport, verify_posture
from .buffered import Buffered
from .compile import CACHE_SIZE, initial_guess, layout_of
from .problem import Problem, Program, SolverOptions
from .result import ContactForce, Result, after_failed, by_method_of, counted
from .runs import (
    _IPOPT_OK,
    BUDGET,
    Budget,
    Run,
    block_multipliers,
    budget_left,
    map_collision_multipliers,
    per_block,
    run_nlp,
)
from .starts import START_MU_INIT, START_WARM_MU_INIT, Solved, carried, start_vector

# Sphere pairs that entered the program of earlier problems of the same structure, and the
# capacity of its collision rows: the next problem of that structure starts with them, so that
# its first run already has the rows it is likely to need, in the program already built (the
# capacity only grows: a planner's next query never meets another program).
_LEARNED: BoundedCache[tuple[frozenset[tuple[int, int]], frozenset[tuple[int, int]], Capacity]] = (
    BoundedCache("learned active sets", 64)
)


@contextlib.contextmanager
def own_learning() -> Iterator[None]:
    """Inside, solves learn active sets and capacities of their own, from none, as in a new
    process; the process's are back after. What runs inside is then a function of its inputs,
    not of what the process solved before (a plan: ATLAS' 2-step stairs was reached in the
    test suite, after other tests had filled the learned sets, and not from a fresh process)."""
    global _LEARNED
    outer = _LEARNED
    _LEARNED = BoundedCache("learned active sets (own)", 64, register=False)
    try:
        yield
    finally:
        _LEARNED = outer


# Learned pairs start the next problem's active set: up to 160 of them. Up to 1000 (Talos'
# first active set at half-sitting holds 427 sphere pairs), HRP-2's vertical ladder failed at
# 'left foot on rung 2' (infeasible): rows learned from the earlier stages and from the
# solve's own continuations held it where it could not move.
_LEARNED_MAX_PAIRS = 160
# collision rows start close to active: a smaller initial barrier parameter took 32 instead
# of 44 median iterations on talos-near-body-collision (n = 20, mu_init 1e-2 against IPOPT's
# 0.1); with the separated start (collision.separated_start) 1e-3 took 22.5 and 21.0 (two
# seeds) against 25.0 and 23.5 at 1e-2; talos-box-collision 19.5 and 18 either way
COLLISION_MU_INIT = 1e-3
# the barrier parameter of a cold run after a warm-started round failed: IPOPT's default. The
# rows that entered can be far from the last posture's multipliers (HRP-2's vertical ladder,
# right foot on rung 1: 157 -> 258 self pairs, 400 iterations warm; 52 cold at 0.1)
RETRY_MU_INIT = 0.1
# IPOPT's first Hessian regularization and its growth while the inertia is wrong, for the
# collision runs: sphere-box rows pressed near a box edge and sphere pairs sliding on each
# other bend the Lagrangian down (eigenvalues to -400 at Talos' box solutions)
COLLISION_PERTURBATION: tuple[float, float] | None = (1e-3, 10.0)


# Torque continuation: a program that IPOPT found locally infeasible is solved with its torque
# limits ×TORQUE_CONTINUATION, and the real one again from that solution. Talos' inclined
# ladder, stage 'left foot on step 2', with a Euclidean sphere-box distance that was tried
# (commit 54894ca): from the previous stage's posture, infeasible after 246 iterations (the
# knee needed 1.14× its limit there); with the limits ×2, 41 iterations, then 29 from that
# posture: verified.
TORQUE_CONTINUATION = 2.0


def solve(problem: Problem, x0: np.ndarray | None = None, start: Solved | None = None) -> Result:
    """Solve the posture problem and verify the posture; never raises for 'not found'.

    With collision avoidance, IPOPT runs in an active-set loop (see posturegen.collision.rows):
    the rows of the pairs that are close enter the program, the solution is checked against
    every candidate pair, violated pairs are added and IPOPT runs again, warm-started; but a
    round's posture stands, and the rounds end there, when the real meshes of every pair
    whose proxies are closer than their clearance keep that clearance (coal) and it passes
    the re-check (a note names those pairs). If the posture fails the mesh check, the margin
    grows by 1 cm and the loop runs again.
    The pairs used are remembered per problem structure; the next problem of that structure
    starts with them. When IPOPT does not converge, two continuations follow: without the
    collision rows, then with the torque limits relaxed (for the SQP, only when a torque row
    bound one of its steps), each solution starting the real program again. A stance whose
    fixed contacts place two links' meshes into each other cannot pass the mesh check: one
    run without collision rows, and the message says so
    (:func:`posturegen.collision.active_set.placed_blocked`). ``max_call_iter`` bounds the
    whole call, each run to what is left of it. Under ``auto`` the call is the SQP's, and
    when it fails IPOPT's from the same start (each with its own budget): an SQP round that
    succeeds ends elsewhere than IPOPT's, and the next rounds follow it, so that IPOPT from
    the SQP's failed round could fail where IPOPT alone verifies. The Result counts every
    run (a stance its fixed contacts block: the SQP's alone). Why a failure failed:
    :func:`posturegen.solver.diagnose.diagnose`.

    ``x0``: the variables to start from (this problem's layout); ``start``: a solved posture
    of the same robot to start from instead (:mod:`posturegen.solver.starts`; a planner's
    nearest solution): without collision avoidance its multipliers too (IPOPT's warm start,
    SolverOptions.warm_start), else its variables, the active-set loop's own barrier
    parameter then (COLLISION_MU_INIT). The continuations start from its variables.

    Args:
        problem: the posture problem (never written on: it can be solved from threads).
        x0: (nx,) the program's variables to start from, in this problem's layout.
        start: a solved Result of the same robot to warm-start from.

    Returns:
        A frozen :class:`Result`: ``success`` (re-checked on Pinocchio and the meshes), ``q``
        (nq,) [m, quaternion xyzw, rad], ``torques`` (nj,) [N·m], ``forces`` per contact
        [N at points in m], ``status``, ``iterations``, timings [s], ``verification``."""
    t0 = time.perf_counter()
    if problem.solver_options.solver_method() != "auto":
        result = _budgeted(problem, x0, start)
    else:  # the SQP's call, then IPOPT's from the same start when it fails
        result = _budgeted(_using(problem, "sqp"), x0, start)
        if not result.success and placed_blocked(Program.of(problem)) is None:
            result = after_failed(result, _budgeted(_using(problem, "ipopt"), x0, start))
    return dataclasses.replace(result, wall_time_s=time.perf_counter() - t0)


def _using(problem: Problem, method: str) -> Problem:
    """``problem`` solved by ``method`` (the same structure: the method is not part of it)."""
    options = dataclasses.replace(problem.solver_options, method=method)
    return dataclasses.replace(problem, solver_options=options)


def _budgeted(problem: Problem, x0: np.ndarray | None, start: Solved | None) -> Result:
    """:func:`_solve` under a budget of its own (SolverOptions.max_call_iter)."""
    token = BUDGET.set(Budget(problem.solver_options.max_call_iter))
    try:
        return _solve(problem, x0, start)
    finally:
        BUDGET.reset(token)


def _solve(problem: Problem, x0: np.ndarray | None, start: Solved | None) -> Result:
    """:func:`solve` within its call's budget."""
    x_start = None if x0 is None else np.asarray(x0, dtype=float)
    program = Program.of(problem)
    first, duals = program, None
    if start is not None and x_start is None:
        first, x_start, duals = _started(program, start)
    result, runs = _solve_continued(first, x_start, [], duals)
    effort = problem.robot.effort_limit
    if result.success or result.status in _IPOPT_OK or not np.any(np.isfinite(effort)):
        return result
    if not budget_left() or not _torque_limits_bound(runs):
        return result
    relaxed = program.but(torque_limit_scale=program.torque_limit_scale * TORQUE_CONTINUATION)
    _, relaxed_runs = _solve_continued(relaxed, x_start, runs)
    if relaxed_runs[-1].status not in _IPOPT_OK:
        return counted(result, relaxed_runs)
    retry, retry_runs = _solve_continued(program, relaxed_runs[-1].x, relaxed_runs)
    return retry if retry.success else counted(result, retry_runs)


def _torque_limits_bound(runs: list[Run]) -> bool:
    """Whether relaxing the torque limits can change a run: an IPOPT run's barrier sees every
    bound; an SQP run's steps are the same unless a torque row was violated at an iterate,
    had a multiplier in a step's QP or was within reach of a region whose QP had no solution
    (SQPRun.rows_bound; else, relaxed, the same steps hold and stay optimal, and the
    continuation would replay its runs)."""
    for run in runs:
        if run.rows_bound is None:
            return True
        rows = run.compiled.g_index.get(TORQUE_LIMITS)
        if rows is not None and run.rows_bound[rows].any():
            return True
    return False


# the outputs' call per function, into preallocated arrays (posturegen.solver.buffered)
_OUTPUT_CALLS: BoundedCache[Buffered] = BoundedCache("output calls", CACHE_SIZE)


def _outputs(run: Run) -> dict[str, np.ndarray]:
    """The program's outputs at a run's solution, flattened (column-major)."""
    fn = run.compiled.outputs
    with run.compiled.lock:  # the call's arrays are the structure's: one at a time
        call = _OUTPUT_CALLS.get_or_make(Ref(fn), lambda: Buffered(fn))
        call.arg("x")[:] = run.x
        call.arg("p")[:] = run.p
        call()
        return {fn.name_out(i): call.column(i) for i in range(fn.n_out())}


def _solve_continued(
    program: Program,
    x_start: np.ndarray | None,
    prior: list[Run],
    duals: tuple[np.ndarray, dict[str, np.ndarray]] | None = None,
) -> tuple[Result, list[Run]]:
    """One solve from ``x_start`` (the active-set loop with collision avoidance, and the
    collision continuation when it fails); ``prior`` runs count in the Result. Returns the
    Result and every run so far. ``duals``: (lam_x, lam_g per block) of a warm start
    (without collision avoidance)."""
    program = program.but(collision_term=None)
    if program.collision_options is None:
        lam_x0, lam_g0 = duals if duals is not None else (None, None)
        runs = [*prior, *run_nlp(program, x_start, lam_x0, lam_g0)]
        return _result(program, runs), runs
    blocked = placed_blocked(program)
    if blocked is not None:  # no posture passes: one run without collision rows, and why
        runs = [*prior, *run_nlp(_without_rows(program), x_start)]
        result = _result(program, runs)
        return (result if result.success else _explained(result, blocked)), runs
    result, runs = _solve_avoiding(program, x_start, prior)
    if result.success:
        return result, runs
    # Continuation: without collision rows (the same program, every pair let go) it often
    # converges where the full one stops infeasible (a far warm start, many rows becoming
    # active at once); its solution then starts the full program. On the inclined ladder
    # (HRP-2, left foot to step 2): 355 iterations, infeasible; 22 without collisions, then
    # 264 from there, verified.
    if not budget_left():
        return result, runs
    relaxed = run_nlp(_without_rows(program), x_start)
    if not relaxed[-1].ok:
        return counted(result, [*runs, *relaxed]), [*runs, *relaxed]
    return _solve_avoiding(program, relaxed[-1].x, [*runs, *relaxed])


def _learned_key(program: Program, active: ActiveSet) -> tuple[Any, ...]:
    """What the pairs and the capacity learned from earlier problems are kept under."""
    opts = program.collision_options
    return (program.key(), len(active.boxes), opts.self_collision, opts.exclude)


def _without_rows(program: Program) -> Program:
    """The program with its collision rows but no pair held (every row free: unbounded, a
    constant), in the capacity its problems have learned: the same structure as its collision
    runs, so that a run without collision avoidance compiles nothing more."""
    active = ActiveSet.of(program)
    _, _, capacity = _LEARNED.get(
        _learned_key(program.but(collision_term=None), active),
        (frozenset(), frozenset(), Capacity()),
    )
    active.capacity = capacity
    return program.but(collision_term=active.term(program.collision_options.margin))


def _solve_avoiding(
    program: Program,
    x0: np.ndarray | None,
    prior: list[Run],
    layout: dict[str, slice] | None = None,
) -> tuple[Result, list[Run]]:
    """The active-set loop of :func:`solve` from ``x0`` (laid out as ``layout``, default
    this program's); ``prior`` runs count in the Result's iterations and times. Returns the
    Result and every run so far."""
    program = program.but(collision_term=None)
    opts = program.collision_options
    active = ActiveSet.of(program)
    joints0 = None  # IPOPT's first start: q_init with its pressed self pairs parted
    if x0 is None and len(active.links) and program.solver_options.solver_method() == "ipopt":
        joints0 = separated_start(
            program.robot,
            active.pm,
            active.links,
            opts.margin,
            program.q_init,
            [c.patch.joint_id for c in program.contacts],
        )
    base_key = _learned_key(program, active)
    learned_self, learned_env, capacity = _LEARNED.get(
        base_key, (frozenset(), frozenset(), Capacity())
    )
    active.self_pairs, active.env_pairs = set(learned_self), set(learned_env)
    active.capacity = capacity
    run_options = _collision_solver_options(program.solver_options)
    loop = _Loop(program.but(solver_options=run_options), active, run_options, x0, joints0, layout)
    result: Result | None = None
    for _attempt in range(opts.tighten + 1):
        result = _rounds(program, prior, loop, opts.max_rounds)
        held = (learned_self, learned_env)  # too many pairs: the earlier ones kept
        if len(active.self_pairs) + len(active.env_pairs) <= _LEARNED_MAX_PAIRS:
            held = (frozenset(active.self_pairs), frozenset(active.env_pairs))
        _LEARNED.put(base_key, (*held, active.capacity))
        if result.success or loop.runs[-1].status not in _IPOPT_OK:
            return result, [*prior, *loop.runs]
        if not any(c.name.startswith("collision") for c in result.verification.failures):
            return result, [*prior, *loop.runs]
        if not budget_left():
            return result, [*prior, *loop.runs]
        loop.margin += TIGHTEN_STEP  # the proxies passed but a mesh did not: tighten, retry
    return result, [*prior, *loop.runs]  # type: ignore[return-value]


def _rounds(program: Program, prior: list[Run], loop: _Loop, max_rounds: int) -> Result:
    """The loop's rounds and their Result: the last run's, or the posture that stood
    (:func:`_standing_result`); a posture that stood but does not pass the re-check lets the
    rounds go on."""
    loop.rounds(max_rounds)
    if loop.stood is not None:
        stood = _standing_result(program, prior, loop, loop.stood)
        if stood is not None:
            return stood
        loop.stand_early, loop.stood = False, None
        loop.rounds(max_rounds)
    return _result(program, [*prior, *loop.runs], loop.margin)


def _standing_result(
    program: Program,
    prior: list[Run],
    loop: _Loop,
    standing: dict[tuple[int, int], tuple[float, float]],
) -> Result | None:
    """The Result of the posture that stood (``standing``: :meth:`_Loop.standing`), its note
    naming the pairs whose meshes keep the clearance their proxies do not; None when it does
    not pass the re-check."""
    result = _result(program, [*prior, *loop.runs], loop.margin)
    if not result.success:
        return None
    names = program.robot.model.names
    note = "the meshes keep the clearance their proxies do not: " + ", ".join(
        f"{names[a]}/{names[b]} at least {1e3 * mesh:.1f} mm apart >= {1e3 * clearance:.1f} mm"
        for (a, b), (clearance, mesh) in sorted(standing.items())
    )
    report = result.verification
    result.posture["notes"].append(note)
    report = VerifyReport(report.checks, (*report.notes, note))
    return dataclasses.replace(result, verification=report)


def _collision_solver_options(options: SolverOptions) -> SolverOptions:
    """The options of the collision runs: COLLISION_MU_INIT and COLLISION_PERTURBATION
    unless the problem sets its own."""
    if options.mu_init is None:
        options = dataclasses.replace(options, mu_init=COLLISION_MU_INIT)
    if COLLISION_PERTURBATION is not None and options.first_hessian_perturbation is None:
        first, factor = COLLISION_PERTURBATION
        options = dataclasses.replace(
            options, first_hessian_perturbation=first, perturb_inc_fact_first=factor
        )
    return options


@dataclass
class _Loop:
    """The state of the active-set loop: the runs so far, the warm start, the margin."""

    program: Program  # the problem with the collision runs' solver options
    active: ActiveSet
    cold_run: SolverOptions
    x_warm: np.ndarray | None
    joints0: np.ndarray | None
    layout: dict[str, slice] | None = None  # the blocks of x_warm when not this program's
    runs: list[Run] = dataclasses.field(default_factory=list)
    lam: dict[str, Any] | None = None
    margin: float = 0.0
    stand_early: bool = True  # a converged round's posture may stand (standing)
    # the rounds ended at a posture that stood: standing()'s pairs there
    stood: dict[tuple[int, int], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        self.margin = self.program.collision_options.margin
        self.q_check = self.program.q_init

    def rounds(self, max_rounds: int) -> None:
        """Up to ``max_rounds`` IPOPT runs, each after holding the pairs near (and violated
        at) the last posture; ends when no candidate pair outside the held ones is violated
        or a run fails."""
        active = self.active
        for _round in range(max_rounds):
            scan = active.scan(self.q_check, self.margin, near=not self.runs)
            if self.runs and not scan.violated:
                return  # no candidate outside the active set is violated
            if self.runs and not budget_left():
                return  # the call's budget is spent: the re-check says what is violated
            self.stood = self.standing(scan) if self.runs and self.stand_early else None
            if self.stood is not None:
                return  # the meshes keep what the proxies do not: the re-check decides
            active.grow(scan)
            term = active.term(self.margin)
            run = self._run(term)
            if run.status not in _IPOPT_OK:
                return
            self.x_warm = run.x
            self.lam = block_multipliers(run, term)
            self.q_check = configuration_from_x(run.program, run.compiled, run.x)

    def standing(self, scan: Scan) -> dict[tuple[int, int], tuple[float, float]] | None:
        """At the last run's posture (``q_check``, converged; ``scan`` made there): the pairs
        of links whose proxies are closer than their clearance, each with that clearance and
        a lower bound of its meshes' distance [m] (:func:`mesh_clearances`: coal on the real
        meshes where their hulls come closer), when every such bound keeps the clearance;
        None otherwise, or when a sphere-box pair or a joint map is violated
        there. The proxies are spheres fitted within 1 cm outside the meshes: the meshes of
        a pair whose proxies are too close are often far enough apart, and the next round's
        run (the pair's rows added, violated) is the longest of a call (a stance's thighs:
        29-150 iterations)."""
        if scan.box_or_map_violated:
            return None
        robot = self.program.robot
        meshes = mesh_clearances(robot.model, robot.collision_model(), self.q_check, scan.below)
        held = {pair: (clearance, meshes[pair]) for pair, clearance in scan.below.items()}
        return held if all(mesh >= clearance for clearance, mesh in held.values()) else None

    def _run(self, term: CollisionTerm) -> Run:
        """IPOPT on the program with ``term``'s rows: from the first start, or warm (primal
        and dual) from the last run; a warm run that fails is followed by a cold one from the
        same posture with IPOPT's default barrier parameter (RETRY_MU_INIT). Both count."""
        if self.lam is None:
            program = self.program.but(collision_term=term, solver_options=self.cold_run)
            self.runs += run_nlp(program, self.x_warm, joints0=self.joints0, layout=self.layout)
            return self.runs[-1]
        warm = dataclasses.replace(self.cold_run, warm_start=True)
        program = self.program.but(collision_term=term, solver_options=warm)
        lam = map_collision_multipliers(self.lam, term)
        layout = self.runs[-1].compiled.x_index
        self.runs += run_nlp(program, self.x_warm, self.runs[-1].lam_x, lam, layout=layout)
        if self.runs[-1].ok or not budget_left():
            return self.runs[-1]
        cold = dataclasses.replace(self.cold_run, mu_init=RETRY_MU_INIT)
        self.runs += run_nlp(program.but(solver_options=cold), self.x_warm, layout=layout)
        return self.runs[-1]


def _message(status: str, report: VerifyReport, method: str = "ipopt") -> str:
    """Why a solve failed, or "verified"."""
    name = {"ipopt": "IPOPT", "sqp": "the SQP"}.get(method, method)
    if status not in _IPOPT_OK:
        return f"{name} did not converge ({status})"
    if report.ok:
        return "verified"
    return f"{name} converged but the re-check failed: " + "; ".join(
        f"{c.name} {c.value:.3g} > {c.tolerance:.1g}" + (f" ({c.detail})" if c.detail else "")
        for c in report.failures
    )


def _explained(result: Result, why: str) -> Result:
    """The failed ``result`` with ``why`` leading its message (and its posture's)."""
    message = f"{why} ({result.message})"
    result.posture["message"] = message
    return dataclasses.replace(result, message=message)


def _started(
    program: Program, start: Solved
) -> tuple[Program, np.ndarray, tuple[np.ndarray, dict[str, np.ndarray]] | None]:
    """The first program of a solve from ``start``, its variables laid out for it, and its
    multipliers when the program has no collision rows and the start has them (IPOPT's warm
    start from START_WARM_MU_INIT; else the barrier from START_MU_INIT unless the options set
    one)."""
    layout = layout_of(program)  # the variables' blocks (no solver built)
    x_init = initial_guess(program, layout)
    x = start_vector(program, x_init, layout.x_index, start)
    if program.collision_options is not None:
        return program, x, None
    options = program.solver_options
    if start.lam_x.size and start.lam_g:
        lam_x = carried(start.lam_x, start.x_blocks, layout.x_index, np.zeros_like(x))
        warm = dataclasses.replace(options, warm_start=True, warm_mu_init=START_WARM_MU_INIT)
        return program.but(solver_options=warm), x, (lam_x, dict(start.lam_g))
    if options.mu_init is None:
        options = dataclasses.replace(options, mu_init=START_MU_INIT)
    return program.but(solver_options=options), x, None


def _result(program: Program, runs: list[Run], margin: float | None = None) -> Result:
    """The Result of the last run (times and iterations summed over every run)."""
    run = runs[-1]
    outputs = _outputs(run)
    q = configuration_from_x(program, run.compiled, run.x)
    torques = outputs["torques"]
    posture = posture_dict(program, q, torques, outputs, margin)
    geometry = program.robot.collision_model() if program.collision_options is not None else None
    t_verify = time.perf_counter()
    report = verify_posture(posture, program.robot.model, geometry)
    verify_time = time.perf_counter() - t_verify
    status = run.status
    success = status in _IPOPT_OK and report.ok
    message = _message(status, report, run.method)
    budget = BUDGET.get()
    if not success and budget is not None and not budget.left():
        message = (
            f"the call's {budget.limit} iterations (options.solver.max_call_iter) were "
            f"spent: {message}"
        )
    iterations = sum(r.iterations for r in runs)
    solve_time = sum(r.solve_time_s for r in runs)
    add_solve_fields(posture, success, status, message, iterations, solve_time, len(runs), report)
    forces = {
        c["name"]: tuple(
            ContactForce(f["frame"], np.array(f["point"]), np.array(f["force"]))
            for f in c["forces"]
        )
        for c in posture["contacts"]
    }
    return Result(
        success=success,
        status=status,
        message=message,
        iterations=iterations,
        solve_time_s=solve_time,
        build_time_s=sum(r.build_time_s for r in runs),
        q=q,
        torques=torques,
        forces=forces,
        cost=run.f,
        verification=report,
        posture=posture,
        constraint_rows=run.compiled.n_g,
        generated_c=run.compiled.library,
        x=run.x,
        x_blocks=dict(run.compiled.x_index),
        lam_x=np.zeros(0) if run.lam_x is None else run.lam_x,
        lam_g=per_block(run),
        method=run.method,
        iterations_by_method=by_method_of(runs),
        verify_time_s=verify_time,
    )


def configuration_from_x(problem: Problem | Program, compiled: Any, x: np.ndarray) -> np.ndarray:
    """Pinocchio q (nq,) from the solver's variables: R = R0·exp(w) computed exactly."""
    p = x[compiled.x_index["base.position"]]
    w = x[compiled.x_index["base.rotation"]]
    qj = x[compiled.x_index["joints"]]
    R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
    quat = pin.Quaternion(R0 @ pin.exp3(w)).normalized().coeffs()  # (x, y, z, w)
    return np.concatenate([p, quat, qj])
