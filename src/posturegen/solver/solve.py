"""Solving a :class:`~posturegen.solver.problem.Problem`: IPOPT, then an independent re-check.

``solve`` returns a frozen :class:`Result`. ``success`` is True only when IPOPT converged AND
:func:`posturegen.verify.verify_posture` (Pinocchio, not CasADi) accepts the posture.
"""

from __future__ import annotations

import dataclasses
import time
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._cache import BoundedCache
from ..collision.active_set import ActiveSet, placed_blocked
from ..collision.boxes import TIGHTEN_STEP
from ..collision.rows import CollisionTerm
from ..collision.separation import separated_start
from ..io.posture_file import add_solve_fields, posture_dict, write_posture
from ..verify import VerifyReport, verify_posture
from .compile import CompiledNLP, initial_guess, is_compiled, layout_of
from .problem import Problem, Program, SolverOptions
from .starts import START_MU_INIT, START_WARM_MU_INIT, Solved, carried, start_vector

_IPOPT_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass(frozen=True)
class ContactForce:
    """A force on the robot [N] at a world point [m], applied to a point of ``frame``."""

    frame: str
    point: np.ndarray  # (3,) world [m]
    force: np.ndarray  # (3,) world [N]


@dataclass(frozen=True)
class Result:
    """A solved posture. ``success`` means IPOPT converged and the re-check passed."""

    success: bool
    status: str  # IPOPT's return status
    message: str  # why it failed, or "verified"
    iterations: int
    solve_time_s: float  # IPOPT's own wall time [s]
    build_time_s: float  # time to build the solver (0 when it came from the cache) [s]
    q: np.ndarray  # (nq,) Pinocchio order: base xyz, quaternion xyzw, joints
    torques: np.ndarray  # (nj,) actuated joints, velocity order [N·m]
    forces: dict[str, tuple[ContactForce, ...]]  # per contact name
    cost: float
    verification: VerifyReport
    posture: dict[str, Any]  # the posture-file content
    # why no posture was found, one line (posturegen.solver.diagnose.diagnose); "" when not
    # diagnosed
    diagnosis: str = ""
    # the last IPOPT run's program: its constraint rows (its collision rows included) and
    # whether it ran generated C (posturegen.solver.codegen)
    constraint_rows: int = 0
    generated_c: bool = False
    # the last run's variables (n_x,) and their blocks: what starts another solve
    # (solve(problem, start=result))
    x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    x_blocks: dict[str, slice] = dataclasses.field(default_factory=dict)
    # and its multipliers: of the variables' bounds (n_x,), of each constraint block
    lam_x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    lam_g: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)

    @property
    def max_violation(self) -> float:
        """The worst re-check relative to its tolerance (<= 1: all passed; see
        :attr:`VerifyReport.max_violation`)."""
        return self.verification.max_violation

    def write(self, path: str | Path) -> Path:
        """Write the posture file (JSON)."""
        return write_posture(path, self.posture)


@dataclass
class _Budget:
    """The IPOPT iterations one call of :func:`solve` may spend (SolverOptions.max_call_iter)
    and has spent: each run is charged; once spent, no run starts."""

    limit: int | None
    spent: int = 0

    def left(self) -> bool:
        return self.limit is None or self.spent < self.limit

    def run_cap(self, max_iter: int) -> int:
        """The next run's iteration limit: ``max_iter``, or what is left of the budget rounded
        up to a multiple of BUDGET_STEP when less (a few solver variants per structure, not
        one per count), so that a call spends at most its budget + BUDGET_STEP - 1."""
        if self.limit is None:
            return max_iter
        left = max(self.limit - self.spent, 1)
        return min(max_iter, -(-left // BUDGET_STEP) * BUDGET_STEP)


# [iterations] a run's limit under a call's budget: what is left, rounded up to this
BUDGET_STEP = 25

# the budget of the solve running in this thread (or task); outside a solve, unbounded
_BUDGET: ContextVar[_Budget | None] = ContextVar("posturegen_call_budget", default=None)


def _budget_left() -> bool:
    """True while the running call may start another IPOPT run."""
    budget = _BUDGET.get()
    return budget is None or budget.left()


@dataclass
class _Run:
    """One IPOPT run: its solution and what it cost."""

    program: Program  # what the run solved: the problem with this run's overrides
    compiled: CompiledNLP
    x: np.ndarray
    p: np.ndarray
    f: float
    status: str
    iterations: int
    solve_time_s: float
    build_time_s: float
    lam_x: np.ndarray | None = None
    lam_g: np.ndarray | None = None


def _run_ipopt(
    program: Program,
    x0: np.ndarray | None,
    lam_x0: np.ndarray | None = None,
    lam_g0: dict[str, np.ndarray] | None = None,
    joints0: np.ndarray | None = None,
    layout: dict[str, slice] | None = None,
) -> _Run:
    """One IPOPT run; with ``lam_g0`` (multipliers per constraint block) a warm start; without
    ``x0``, the problem's initial guess with ``joints0`` (nj,) for the joints when given.
    ``layout``: the variable blocks of ``x0`` and ``lam_x0`` when they may differ from this
    program's (an elastic program's collision slacks grow with the active set)."""
    budget = _BUDGET.get()
    options = program.solver_options
    cap = options.max_iter if budget is None else budget.run_cap(options.max_iter)
    if cap < options.max_iter:  # the call's budget ends within this run
        program = program.but(solver_options=dataclasses.replace(options, max_iter=cap))
    built_before = is_compiled(program)
    compiled = program.compile()
    with compiled.lock:
        compiled.refresh()  # generated C once it is built (posturegen.solver.codegen)
    x_init, p, lbg, ubg = program.numeric(compiled)
    if x0 is not None and layout is not None and layout != compiled.x_index:
        x0 = carried(x0, layout, compiled.x_index, x_init)
        if lam_x0 is not None:
            lam_x0 = carried(lam_x0, layout, compiled.x_index, np.zeros_like(x_init))
    if x0 is not None and x0.shape == x_init.shape:
        x_init = x0
    elif joints0 is not None:
        x_init[compiled.x_index["joints"]] = joints0
    warm: dict[str, Any] = {}
    if lam_g0 is not None and lam_x0 is not None:
        lam = np.zeros(compiled.n_g)
        for name, sl in compiled.g_index.items():
            if name in lam_g0 and lam_g0[name].size == sl.stop - sl.start:
                lam[sl] = lam_g0[name]
        warm = {"lam_x0": lam_x0, "lam_g0": lam}
    with compiled.lock:  # a solver's stats() are those of its last call: one thread at a time
        t0 = time.perf_counter()
        sol = compiled.solver(
            x0=x_init, p=p, lbx=compiled.lbx, ubx=compiled.ubx, lbg=lbg, ubg=ubg, **warm
        )
        wall = time.perf_counter() - t0
        stats = compiled.solver.stats()
    run = _Run(
        program=program,
        compiled=compiled,
        x=np.array(sol["x"]).ravel(),
        p=p,
        f=float(sol["f"]),
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        solve_time_s=float(stats.get("t_wall_total", wall)),
        build_time_s=0.0 if built_before else compiled.build_time_s,
        lam_x=np.array(sol["lam_x"]).ravel(),
        lam_g=np.array(sol["lam_g"]).ravel(),
    )
    if budget is not None:
        budget.spent += max(run.iterations, 0)
    return run


def _per_block(run: _Run) -> dict[str, np.ndarray]:
    """The run's constraint multipliers per block (none without them)."""
    if run.lam_g is None:
        return {}
    return {name: run.lam_g[sl] for name, sl in run.compiled.g_index.items()}


def _block_multipliers(run: _Run, term: Any) -> dict[str, np.ndarray]:
    """The last run's constraint multipliers per block; collision rows keyed by their pair so
    that they survive the growth of the active set (see _map_collision_multipliers)."""
    out: dict[str, Any] = _per_block(run)
    if term is not None:
        if "collision.self" in out:
            keys = [k for k, _ in term.self_groups()]
            out["collision.self"] = dict(zip(keys, out["collision.self"], strict=True))
        if "collision.env" in out:
            rows = zip(term.env_rows(), out["collision.env"], strict=True)
            out["collision.env"] = {pair: lam for pair, lam in rows if pair is not None}
    return out


def _map_collision_multipliers(lam: dict[str, Any], term: Any) -> dict[str, np.ndarray]:
    """Multipliers for the new active set: old pairs keep theirs, new pairs start at 0."""
    out = {k: v for k, v in lam.items() if isinstance(v, np.ndarray)}
    groups = [k for k, _ in term.self_groups()]
    for block, pairs in (("collision.self", groups), ("collision.env", term.env_rows())):
        old = lam.get(block)
        if pairs:
            old = old if isinstance(old, dict) else {}
            out[block] = np.array([0.0 if p is None else old.get(p, 0.0) for p in pairs])
    return out


# Sphere pairs that entered the program of earlier problems of the same structure: the next
# problem of that structure starts with them, so that its program is usually the same one
# (a planner's next query pays no rebuild, and its first run already has the right rows).
_LEARNED: BoundedCache[tuple[frozenset[tuple[int, int]], frozenset[tuple[int, int]]]] = (
    BoundedCache("learned active sets", 64)
)
# Learned pairs start the next problem's active set: up to 160 of them. Up to 1000 (Talos'
# first active set at half-sitting holds 427 sphere pairs), HRP-2's vertical ladder failed at
# 'left foot on rung 2' (infeasible): rows learned from the earlier stages and from the
# solve's own continuations held it where it could not move.
_LEARNED_MAX_PAIRS = 160
# A solve's rows fill the slots of a layout (rows.Layout: 16 per joint pair, 4 per link and
# box) that grows over its rounds: two active sets of the same joint pairs share a compiled
# program. Layouts are not carried from one problem to the next: united over a structure's
# solves, their constant rows of free slots changed IPOPT's path (its KKT systems grew), and
# HRP-2's vertical ladder ('left foot on rung 2') and Talos' stairs ('right foot on step 3')
# failed where they verify without.
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
    every candidate pair, violated pairs are added and IPOPT runs again, warm-started. If the
    posture then fails the mesh check, the margin grows by 1 cm and the loop runs again.
    The pairs used are remembered per problem structure; the next problem of that structure
    starts with them. When IPOPT does not converge, two continuations follow: without the
    collision rows, then with the torque limits relaxed, each solution starting the real
    program again. A stance whose fixed contacts place two links' meshes into each other
    cannot pass the mesh check: one run without collision rows, and the message says so
    (:func:`posturegen.collision.active_set.placed_blocked`). ``max_call_iter`` bounds the
    whole call, each run to what is left of it. The Result counts every IPOPT run. Why a
    failure failed: :func:`posturegen.solver.diagnose.diagnose`.

    ``x0``: the variables to start from (this problem's layout); ``start``: a solved posture
    of the same robot to start from instead (:mod:`posturegen.solver.starts`; a planner's
    nearest solution): without collision avoidance its multipliers too (IPOPT's warm start,
    SolverOptions.warm_start), else its variables, the active-set loop's own barrier
    parameter then (COLLISION_MU_INIT). The continuations start from its variables."""
    token = _BUDGET.set(_Budget(problem.solver_options.max_call_iter))
    try:
        return _solve(problem, x0, start)
    finally:
        _BUDGET.reset(token)


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
    if not _budget_left():
        return result
    relaxed = program.but(torque_limit_scale=program.torque_limit_scale * TORQUE_CONTINUATION)
    _, relaxed_runs = _solve_continued(relaxed, x_start, runs)
    if relaxed_runs[-1].status not in _IPOPT_OK:
        return result
    retry, _ = _solve_continued(program, relaxed_runs[-1].x, relaxed_runs)
    return retry if retry.success else result


def _outputs(run: _Run) -> dict[str, np.ndarray]:
    """The program's outputs at a run's solution, flattened (column-major)."""
    out = run.compiled.outputs(x=run.x, p=run.p)
    return {k: np.array(v).ravel(order="F") for k, v in out.items()}


def _solve_continued(
    program: Program,
    x_start: np.ndarray | None,
    prior: list[_Run],
    duals: tuple[np.ndarray, dict[str, np.ndarray]] | None = None,
) -> tuple[Result, list[_Run]]:
    """One solve from ``x_start`` (the active-set loop with collision avoidance, and the
    collision continuation when it fails); ``prior`` runs count in the Result. Returns the
    Result and every run so far. ``duals``: (lam_x, lam_g per block) of a warm start
    (without collision avoidance)."""
    program = program.but(collision_term=None)
    if program.collision_options is None:
        lam_x0, lam_g0 = duals if duals is not None else (None, None)
        runs = [*prior, _run_ipopt(program, x_start, lam_x0, lam_g0)]
        return _result(program, runs), runs
    blocked = placed_blocked(program)
    if blocked is not None:  # no posture passes: one run without collision rows, and why
        runs = [*prior, _run_ipopt(program.but(collision_options=None), x_start)]
        result = _result(program, runs)
        return (result if result.success else _explained(result, blocked)), runs
    result, runs = _solve_avoiding(program, x_start, prior)
    if result.success:
        return result, runs
    # Continuation: without collision rows the program is smaller and smoother, and it often
    # converges where the full one stops infeasible (a far warm start, many rows becoming
    # active at once); its solution then starts the full program. On the inclined ladder
    # (HRP-2, left foot to step 2): 355 iterations, infeasible; 22 without collisions, then
    # 264 from there, verified.
    if not _budget_left():
        return result, runs
    relaxed = _run_ipopt(program.but(collision_options=None), x_start)
    if relaxed.status not in _IPOPT_OK:
        return result, [*runs, relaxed]
    return _solve_avoiding(program, relaxed.x, [*runs, relaxed])


def _solve_avoiding(
    program: Program,
    x0: np.ndarray | None,
    prior: list[_Run],
    layout: dict[str, slice] | None = None,
) -> tuple[Result, list[_Run]]:
    """The active-set loop of :func:`solve` from ``x0`` (laid out as ``layout``, default
    this program's); ``prior`` runs count in the Result's iterations and times. Returns the
    Result and every run so far."""
    program = program.but(collision_term=None)
    opts = program.collision_options
    active = ActiveSet.of(program)
    joints0 = None  # the first start: q_init with its pressed self pairs parted
    if x0 is None and len(active.links):
        joints0 = separated_start(
            program.robot,
            active.pm,
            active.links,
            opts.margin,
            program.q_init,
            [c.patch.joint_id for c in program.contacts],
        )
    base_key = (program.key(), len(active.boxes), opts.self_collision, opts.exclude)
    learned_self, learned_env = _LEARNED.get(base_key, (frozenset(), frozenset()))
    active.self_pairs, active.env_pairs = set(learned_self), set(learned_env)
    run_options = _collision_solver_options(program.solver_options)
    loop = _Loop(program.but(solver_options=run_options), active, run_options, x0, joints0, layout)
    result: Result | None = None
    for _attempt in range(opts.tighten + 1):
        loop.rounds(opts.max_rounds)
        if len(active.self_pairs) + len(active.env_pairs) <= _LEARNED_MAX_PAIRS:
            _LEARNED.put(base_key, (frozenset(active.self_pairs), frozenset(active.env_pairs)))
        result = _result(program, [*prior, *loop.runs], loop.margin)
        if result.success or loop.runs[-1].status not in _IPOPT_OK:
            return result, [*prior, *loop.runs]
        if not any(c.name.startswith("collision") for c in result.verification.failures):
            return result, [*prior, *loop.runs]
        if not _budget_left():
            return result, [*prior, *loop.runs]
        loop.margin += TIGHTEN_STEP  # the proxies passed but a mesh did not: tighten, retry
    return result, [*prior, *loop.runs]  # type: ignore[return-value]


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
    runs: list[_Run] = dataclasses.field(default_factory=list)
    lam: dict[str, Any] | None = None
    margin: float = 0.0

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
            if self.runs and not (scan.violated_self or scan.violated_env):
                return  # no candidate outside the active set is violated
            if self.runs and not _budget_left():
                return  # the call's budget is spent: the re-check says what is violated
            active.grow(scan)
            term = active.term(self.margin)
            run = self._run(term)
            if run.status not in _IPOPT_OK:
                return
            self.x_warm = run.x
            self.lam = _block_multipliers(run, term)
            self.q_check = configuration_from_x(run.program, run.compiled, run.x)

    def _run(self, term: CollisionTerm) -> _Run:
        """IPOPT on the program with ``term``'s rows: from the first start, or warm (primal
        and dual) from the last run; a warm run that fails is followed by a cold one from the
        same posture with IPOPT's default barrier parameter (RETRY_MU_INIT). Both count."""
        if self.lam is None:
            program = self.program.but(collision_term=term, solver_options=self.cold_run)
            run = _run_ipopt(program, self.x_warm, joints0=self.joints0, layout=self.layout)
            self.runs.append(run)
            return run
        warm = dataclasses.replace(self.cold_run, warm_start=True)
        program = self.program.but(collision_term=term, solver_options=warm)
        lam = _map_collision_multipliers(self.lam, term)
        layout = self.runs[-1].compiled.x_index
        run = _run_ipopt(program, self.x_warm, self.runs[-1].lam_x, lam, layout=layout)
        self.runs.append(run)
        if run.status in _IPOPT_OK or not _budget_left():
            return run
        cold = dataclasses.replace(self.cold_run, mu_init=RETRY_MU_INIT)
        run = _run_ipopt(program.but(solver_options=cold), self.x_warm, layout=layout)
        self.runs.append(run)
        return run


def _message(status: str, report: VerifyReport) -> str:
    """Why a solve failed, or "verified"."""
    if status not in _IPOPT_OK:
        return f"IPOPT did not converge ({status})"
    if report.ok:
        return "verified"
    return "IPOPT converged but the re-check failed: " + "; ".join(
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


def _result(program: Program, runs: list[_Run], margin: float | None = None) -> Result:
    """The Result of the last run (times and iterations summed over every run)."""
    run = runs[-1]
    outputs = _outputs(run)
    q = configuration_from_x(program, run.compiled, run.x)
    torques = outputs["torques"]
    posture = posture_dict(program, q, torques, outputs, margin)
    geometry = program.robot.collision_model() if program.collision_options is not None else None
    report = verify_posture(posture, program.robot.model, geometry)
    status = run.status
    success = status in _IPOPT_OK and report.ok
    message = _message(status, report)
    budget = _BUDGET.get()
    if not success and budget is not None and not budget.left():
        message = (
            f"the call's {budget.limit} IPOPT iterations (options.solver.max_call_iter) were "
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
        lam_g=_per_block(run),
    )


def configuration_from_x(problem: Problem | Program, compiled: Any, x: np.ndarray) -> np.ndarray:
    """Pinocchio q (nq,) from the solver's variables: R = R0·exp(w) computed exactly."""
    p = x[compiled.x_index["base.position"]]
    w = x[compiled.x_index["base.rotation"]]
    qj = x[compiled.x_index["joints"]]
    R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
    quat = pin.Quaternion(R0 @ pin.exp3(w)).normalized().coeffs()  # (x, y, z, w)
    return np.concatenate([p, quat, qj])
