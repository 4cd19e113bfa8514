"""One run of a solver on a :class:`~posturegen.solver.problem.Program`, whichever solver:
the SQP core (:mod:`posturegen.solver.sqp`), IPOPT, or the SQP then IPOPT from the same
start when the SQP fails (``SolverOptions.method``: ``auto``; :func:`~posturegen.solver.solve.
solve` under ``auto`` makes the SQP's whole call first, then IPOPT's, each with a budget of its
own, so that a call's runs are of one solver). A run starts from
given variables and multipliers (a warm start: the SQP's first QP working set is the
multipliers' sign pattern, IPOPT's barrier starts small), is charged to the call's budget of
iterations, and returns a :class:`Run`: its solution, multipliers and what it cost."""

from __future__ import annotations

import dataclasses
import time
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._cache import BoundedCache, Ref
from .buffered import Buffered
from .compile import CACHE_SIZE, STRUCTURE_KEY, CompiledNLP, is_compiled
from .problem import Program
from .sqp.core import Bounds, SQPOptions
from .sqp.native import sqp
from .sqp.oracle import Oracle
from .starts import carried

_IPOPT_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass
class Budget:
    """The iterations one call of :func:`~posturegen.solver.solve.solve` may spend
    (SolverOptions.max_call_iter) and has spent: each run is charged (SQP and IPOPT
    iterations alike); once spent, no run starts. It keeps the call's SQP runs too: a run
    from where one of them started is not made again (:class:`_Tried`)."""

    limit: int | None
    spent: int = 0
    tried: list[_Tried] = dataclasses.field(default_factory=list)

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
BUDGET: ContextVar[Budget | None] = ContextVar("posturegen_call_budget", default=None)


def budget_left() -> bool:
    """True while the running call may start another run."""
    budget = BUDGET.get()
    return budget is None or budget.left()


@dataclass
class Run:
    """One solver run: its solution and what it cost."""

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
    method: str = "ipopt"  # the solver that ran: "sqp" or "ipopt"
    replayed: bool = False  # an SQP run of the call from the same start, not made again
    # (m,) the SQP's rows that bound it (SQPRun.rows_bound); None for IPOPT, whose barrier
    # sees every bound
    rows_bound: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.status in _IPOPT_OK


@dataclass
class _Start:
    """A run's program (its iteration cap applied), compiled, and where it starts."""

    program: Program
    compiled: CompiledNLP
    built_before: bool
    x: np.ndarray
    p: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    lam_x: np.ndarray | None
    lam_g: np.ndarray | None


def _start(
    program: Program,
    x0: np.ndarray | None,
    lam_x0: np.ndarray | None,
    lam_g0: dict[str, np.ndarray] | None,
    joints0: np.ndarray | None,
    layout: dict[str, slice] | None,
) -> _Start:
    """The program under the call's budget, compiled, with its start laid out."""
    budget = BUDGET.get()
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
    lam = None
    if lam_g0 is not None and lam_x0 is not None:
        lam = np.zeros(compiled.n_g)
        for name, sl in compiled.g_index.items():
            if name in lam_g0 and lam_g0[name].size == sl.stop - sl.start:
                lam[sl] = lam_g0[name]
    return _Start(program, compiled, built_before, x_init, p, lbg, ubg, lam_x0, lam)


def run_nlp(
    program: Program,
    x0: np.ndarray | None,
    lam_x0: np.ndarray | None = None,
    lam_g0: dict[str, np.ndarray] | None = None,
    joints0: np.ndarray | None = None,
    layout: dict[str, slice] | None = None,
) -> list[Run]:
    """One run of the program's solver (SolverOptions.method) from ``x0``, warm with
    ``lam_g0`` (multipliers per constraint block) and ``lam_x0``; without ``x0``, the
    problem's initial guess with ``joints0`` (nj,) for the joints when given. ``layout``: the
    variable blocks of ``x0`` and ``lam_x0`` when they may differ from this program's. In
    ``auto``, a failed SQP run is followed by IPOPT from the same start: both are returned,
    the last is the answer."""
    method = program.solver_options.solver_method()
    start = _start(program, x0, lam_x0, lam_g0, joints0, layout)
    if method == "ipopt":
        return [_charged(_ipopt(start))]
    first = _charged(_sqp_once(start))
    if method == "sqp" or first.ok or not budget_left():
        return [first]
    retry = _start(program, x0, lam_x0, lam_g0, joints0, layout)  # the budget left
    return [first, _charged(_ipopt(retry))]


# [scaled units: rad, m, N / robot weight] an SQP run whose start is within this of where a
# run of the same call started (the same structure, parameters, bounds and options; its
# multipliers within it too, relative) would take the same steps: it is not made again. A
# near-body reach whose active-set loop failed ran its collision-free continuation, and the
# loop restarted from there fell back onto the first loop's starts and runs (27, 66, 79 and
# 100 iterations, again)
REPLAY_TOL = 1e-6


@dataclass
class _Tried:
    """An SQP run of the call and where it started."""

    start: _Start
    run: Run

    def repeats(self, start: _Start) -> bool:
        """Whether an SQP run from ``start`` would take this run's steps."""
        old = self.start
        if not _same_structure(start, old) or not _same_options(start, old, self.run):
            return False
        for a, b in ((start.p, old.p), (start.lbg, old.lbg), (start.ubg, old.ubg)):
            if not np.array_equal(a, b):
                return False
        scale = variable_scales(start.compiled, start.program.robot.weight)
        if np.max(np.abs(start.x - old.x) / scale, initial=0.0) > REPLAY_TOL:
            return False
        return _near(start.lam_g, old.lam_g) and _near(start.lam_x, old.lam_x)


def _same_structure(start: _Start, old: _Start) -> bool:
    """The same program (its structure and variable bounds), whatever IPOPT's options: each
    option variant of a structure is a solver of its own (:func:`compile_program`), on the
    same functions."""
    a, b = start.compiled, old.compiled
    if a is b:
        return True
    same_key = a.key[:STRUCTURE_KEY] == b.key[:STRUCTURE_KEY]
    return same_key and np.array_equal(a.lbx, b.lbx) and np.array_equal(a.ubx, b.ubx)


def _same_options(start: _Start, old: _Start, run: Run) -> bool:
    """The same SQP options (its time, its QP backend; IPOPT's own are not read), but for an
    iteration cap that ``run`` did not reach."""
    new_options, old_options = start.program.solver_options, old.program.solver_options
    if (new_options.max_cpu_time, new_options.qp) != (old_options.max_cpu_time, old_options.qp):
        return False
    if new_options.max_iter == old_options.max_iter:
        return True
    capped = run.status == "Maximum_Iterations_Exceeded"
    return not capped and run.iterations <= new_options.max_iter


def _near(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Both absent, or within REPLAY_TOL relative to the larger multiplier."""
    if a is None or b is None:
        return a is None and b is None
    size = max(1.0, float(np.max(np.abs(b), initial=0.0)))
    return a.shape == b.shape and float(np.max(np.abs(a - b), initial=0.0)) <= REPLAY_TOL * size


def _sqp_once(start: _Start) -> Run:
    """The SQP from ``start``, or the run of this call that started there (replayed: no
    iteration, no time)."""
    budget = BUDGET.get()
    tried = [] if budget is None else budget.tried
    for earlier in tried:
        if earlier.repeats(start):
            return dataclasses.replace(
                earlier.run, iterations=0, solve_time_s=0.0, build_time_s=0.0, replayed=True
            )
    run = _sqp(start)
    tried.append(_Tried(start, run))
    return run


def _charged(run: Run) -> Run:
    budget = BUDGET.get()
    if budget is not None:
        budget.spent += max(run.iterations, 0)
    return run


# IPOPT's call per solver, into preallocated arrays (posturegen.solver.buffered): its memory
# (the IPOPT application) and its 18,093 parameters of Talos' collision slots stay in place
_IPOPT_CALLS: BoundedCache[Buffered] = BoundedCache("IPOPT calls", CACHE_SIZE)


def _ipopt(start: _Start) -> Run:
    """IPOPT from ``start`` (warm when it has multipliers and the options say so)."""
    compiled = start.compiled
    warm = start.lam_g is not None and start.lam_x is not None
    with compiled.lock:  # the call's arrays and memory are the structure's: one at a time
        call = _IPOPT_CALLS.get_or_make(Ref(compiled.solver), lambda: Buffered(compiled.solver))
        for name, value in (
            ("x0", start.x),
            ("p", start.p),
            ("lbx", compiled.lbx),
            ("ubx", compiled.ubx),
            ("lbg", start.lbg),
            ("ubg", start.ubg),
            ("lam_x0", start.lam_x if warm else 0.0),
            ("lam_g0", start.lam_g if warm else 0.0),
        ):
            call.arg(name)[:] = value
        t0 = time.perf_counter()
        call()
        wall = time.perf_counter() - t0
        stats = call.stats()
        x, f = call.res("x").copy(), float(call.res("f")[0])
        lam_x, lam_g = call.res("lam_x").copy(), call.res("lam_g").copy()
    return _run_of(
        start,
        "ipopt",
        x=x,
        f=f,
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        solve_time_s=float(stats.get("t_wall_total", wall)),
        lam_x=lam_x,
        lam_g=lam_g,
    )


def _run_of(start: _Start, method: str, **solution: Any) -> Run:
    """The Run of ``method`` from ``start`` with its ``solution`` (x, f, status, iterations,
    solve_time_s, lam_x, lam_g)."""
    compiled = start.compiled
    return Run(
        program=start.program,
        compiled=compiled,
        p=start.p,
        build_time_s=0.0 if start.built_before else compiled.build_time_s,
        method=method,
        **solution,
    )


def variable_scales(compiled: CompiledNLP, weight: float) -> np.ndarray:
    """(n,) the units of the SQP's trust region: 1 for lengths [m] and angles [rad], the
    robot's weight [N] for contact forces."""
    scale = np.ones(compiled.n_x)
    for name, sl in compiled.x_index.items():
        if name.endswith("forces"):
            scale[sl] = weight
    return scale


# the SQP's oracle per solver (its library's functions and their buffers, 1 ms to make on
# Talos' reach: a third of a free call's solve)
_ORACLES: BoundedCache[Oracle] = BoundedCache("SQP oracles", CACHE_SIZE)


def _sqp(start: _Start) -> Run:
    """The SQP from ``start``; its first working set from the start's multipliers."""
    compiled, options = start.compiled, start.program.solver_options
    weight = start.program.robot.weight
    bounds = Bounds(
        compiled.lbx, compiled.ubx, start.lbg, start.ubg, variable_scales(compiled, weight)
    )
    duals = None
    if start.lam_g is not None and start.lam_x is not None:
        duals = np.concatenate([start.lam_x, start.lam_g])
    with compiled.lock:  # the oracle's buffers are the structure's: one run at a time
        oracle = _ORACLES.get_or_make(
            Ref(compiled.solver), lambda: Oracle(compiled.solver, start.p)
        ).set_parameters(start.p)
        run = sqp(
            oracle,
            start.x,
            bounds,
            SQPOptions(max_iter=options.max_iter, max_time_s=options.max_cpu_time, qp=options.qp),
            lam_g0=start.lam_g,
            lam_x0=start.lam_x,
            duals0=duals,
        )
    return _run_of(
        start,
        "sqp",
        x=run.x,
        f=run.f,
        status=run.status,
        iterations=run.iterations,
        solve_time_s=run.wall_s,
        lam_x=run.lam_x,
        lam_g=run.lam_g,
        rows_bound=run.rows_bound,
    )


def per_block(run: Run) -> dict[str, np.ndarray]:
    """The run's constraint multipliers per block (none without them)."""
    if run.lam_g is None:
        return {}
    return {name: run.lam_g[sl] for name, sl in run.compiled.g_index.items()}


def block_multipliers(run: Run, term: Any) -> dict[str, np.ndarray]:
    """The last run's constraint multipliers per block; collision rows keyed by their pair so
    that they survive the growth of the active set (see map_collision_multipliers)."""
    out: dict[str, Any] = per_block(run)
    if term is not None:
        if "collision.self" in out:
            keys = [k for k, _ in term.self_groups()]
            out["collision.self"] = dict(zip(keys, out["collision.self"], strict=True))
        if "collision.env" in out:
            rows = zip(term.env_rows(), out["collision.env"], strict=True)
            out["collision.env"] = {pair: lam for pair, lam in rows if pair is not None}
    return out


def map_collision_multipliers(lam: dict[str, Any], term: Any) -> dict[str, np.ndarray]:
    """Multipliers for the new active set: old pairs keep theirs, new pairs start at 0."""
    out = {k: v for k, v in lam.items() if isinstance(v, np.ndarray)}
    groups = [k for k, _ in term.self_groups()]
    for block, pairs in (("collision.self", groups), ("collision.env", term.env_rows())):
        old = lam.get(block)
        if pairs:
            old = old if isinstance(old, dict) else {}
            out[block] = np.array([0.0 if p is None else old.get(p, 0.0) for p in pairs])
    return out
