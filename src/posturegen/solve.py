"""Solving a :class:`~posturegen.problem.Problem`: IPOPT, then an independent re-check.

``solve`` returns a frozen :class:`Result`. ``success`` is True only when IPOPT converged AND
:func:`posturegen.verify.verify_posture` (Pinocchio, not CasADi) accepts the posture.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .active_set import ActiveSet
from .collision import (
    CollisionTerm,
    env_boxes,
    excluded_joint_ids,
    separated_start,
)
from .pairs import pair_rule, unchecked_entries
from .problem import _CACHE, Problem, SolverOptions
from .verify import SCHEMA, VerifyReport, verify_posture

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
    # why no posture was found, one line (posturegen.diagnose.diagnose); "" when not diagnosed
    diagnosis: str = ""

    @property
    def max_violation(self) -> float:
        """Worst value among the re-check's quantities (see :class:`VerifyReport`)."""
        return self.verification.max_violation

    def write(self, path: str | Path) -> Path:
        """Write the posture file (JSON)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.posture, indent=1))
        return path


@dataclass
class _Run:
    """One IPOPT run: its solution and what it cost."""

    compiled: Any
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
    problem: Problem,
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
    built_before = problem.key() in _CACHE
    compiled = problem.compile()
    compiled.refresh()  # generated C once it is built (posturegen.codegen)
    x_init, p, lbg, ubg = problem.numeric(compiled)
    if x0 is not None and layout is not None and layout != compiled.x_index:
        x0 = _carried(x0, layout, compiled.x_index, x_init)
        if lam_x0 is not None:
            lam_x0 = _carried(lam_x0, layout, compiled.x_index, np.zeros_like(x_init))
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
    t0 = time.perf_counter()
    sol = compiled.solver(
        x0=x_init, p=p, lbx=compiled.lbx, ubx=compiled.ubx, lbg=lbg, ubg=ubg, **warm
    )
    wall = time.perf_counter() - t0
    stats = compiled.solver.stats()
    return _Run(
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


def _carried(
    values: np.ndarray, old: dict[str, slice], new: dict[str, slice], default: np.ndarray
) -> np.ndarray:
    """``values`` laid out by the blocks ``old``, moved to the blocks ``new`` (the blocks of
    another size, or new ones, from ``default``)."""
    out = default.copy()
    for name, sl in new.items():
        src = old.get(name)
        if src is not None and src.stop - src.start == sl.stop - sl.start:
            out[sl] = values[src]
    return out


def _block_multipliers(run: _Run, term: Any) -> dict[str, np.ndarray]:
    """The last run's constraint multipliers per block; collision rows keyed by their pair so
    that they survive the growth of the active set (see _map_collision_multipliers)."""
    out = {name: run.lam_g[sl] for name, sl in run.compiled.g_index.items()}
    if term is not None:
        if "collision.self" in out:
            keys = [k for k, _ in term.self_groups()]
            out["collision.self"] = dict(zip(keys, out["collision.self"], strict=True))
        if "collision.env" in out:
            out["collision.env"] = dict(zip(term.env_pairs, out["collision.env"], strict=True))
    return out


def _map_collision_multipliers(lam: dict[str, Any], term: Any) -> dict[str, np.ndarray]:
    """Multipliers for the new active set: old pairs keep theirs, new pairs start at 0."""
    out = {k: v for k, v in lam.items() if isinstance(v, np.ndarray)}
    groups = [k for k, _ in term.self_groups()]
    for block, pairs in (("collision.self", groups), ("collision.env", term.env_pairs)):
        old = lam.get(block)
        if pairs:
            old = old if isinstance(old, dict) else {}
            out[block] = np.array([old.get(p, 0.0) for p in pairs])
    return out


# Sphere pairs that entered the program of earlier problems of the same structure: the next
# problem of that structure starts with them, so that its program is usually the same one
# (a planner's next query pays no rebuild, and its first run already has the right rows).
_LEARNED: dict[tuple[Any, ...], tuple[frozenset[tuple[int, int]], frozenset[tuple[int, int]]]] = {}
# up to 1000: Talos' first active set at half-sitting holds 427 sphere pairs (16 per pair of
# links), so at 160 nothing was learned and every problem that needed a second round built
# its own structure (1.2 s of CPU each). talos-reach-balance-collision (VM, CPU per call, 25
# problems after 25): 99 ms at 160 (one build in 25 calls: 45 ms of it), 53 ms at 1000 (no
# build; first pass 277 -> 138 ms); talos-stances-collision (20 after 20): 19 of 20 verified,
# 55 mean iterations at 160; 20 of 20, 33 at 1000
_LEARNED_MAX_PAIRS = 1000
# collision rows start close to active: a smaller initial barrier parameter took 32 instead
# of 44 median iterations on talos-near-body-collision (n = 20, mu_init 1e-2 against IPOPT's
# 0.1); with the separated start (collision.separated_start) 1e-3 took 22.5 and 21.0 (two
# seeds) against 25.0 and 23.5 at 1e-2; talos-box-collision 19.5 and 18 either way
COLLISION_MU_INIT = 1e-3
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


def solve(problem: Problem, x0: np.ndarray | None = None) -> Result:
    """Solve the posture problem and verify the posture; never raises for 'not found'.

    With collision avoidance, IPOPT runs in an active-set loop (see posturegen.collision):
    the rows of the pairs that are close enter the program, the solution is checked against
    every candidate pair, violated pairs are added and IPOPT runs again, warm-started. If the
    posture then fails the mesh check, the margin grows by 1 cm and the loop runs again.
    The pairs used are remembered per problem structure; the next problem of that structure
    starts with them. When IPOPT does not converge, two continuations follow: without the
    collision rows, then with the torque limits relaxed, each solution starting the real
    program again. The Result counts every IPOPT run. Why a failure failed:
    :func:`posturegen.diagnose.diagnose`."""
    x_start = None if x0 is None else np.asarray(x0, dtype=float)
    result, runs = _solve_continued(problem, x_start, [])
    effort = problem.robot.effort_limit
    if result.success or result.status in _IPOPT_OK or not np.any(np.isfinite(effort)):
        return result
    scale = problem.torque_limit_scale
    problem.torque_limit_scale = scale * TORQUE_CONTINUATION
    try:
        _, relaxed_runs = _solve_continued(problem, x_start, runs)
    finally:
        problem.torque_limit_scale = scale
    if relaxed_runs[-1].status not in _IPOPT_OK:
        return result
    retry, _ = _solve_continued(problem, relaxed_runs[-1].x, relaxed_runs)
    return retry if retry.success else result


def _outputs(run: _Run) -> dict[str, np.ndarray]:
    """The program's outputs at a run's solution, flattened (column-major)."""
    out = run.compiled.outputs(x=run.x, p=run.p)
    return {k: np.array(v).ravel(order="F") for k, v in out.items()}


def _solve_continued(
    problem: Problem, x_start: np.ndarray | None, prior: list[_Run]
) -> tuple[Result, list[_Run]]:
    """One solve from ``x_start`` (the active-set loop with collision avoidance, and the
    collision continuation when it fails); ``prior`` runs count in the Result. Returns the
    Result and every run so far."""
    opts = problem.collision_options
    problem.collision_term = None
    if opts is None:
        runs = [*prior, _run_ipopt(problem, x_start)]
        return _result(problem, runs), runs
    result, runs = _solve_avoiding(problem, x_start, prior)
    if result.success:
        return result, runs
    # Continuation: without collision rows the program is smaller and smoother, and it often
    # converges where the full one stops infeasible (a far warm start, many rows becoming
    # active at once); its solution then starts the full program. On the inclined ladder
    # (HRP-2, left foot to step 2): 355 iterations, infeasible; 22 without collisions, then
    # 264 from there, verified.
    problem.collision_options, problem.collision_term = None, None
    try:
        relaxed = _run_ipopt(problem, x_start)
    finally:
        problem.collision_options = opts
    if relaxed.status not in _IPOPT_OK:
        return result, [*runs, relaxed]
    return _solve_avoiding(problem, relaxed.x, [*runs, relaxed])


def _solve_avoiding(
    problem: Problem,
    x0: np.ndarray | None,
    prior: list[_Run],
    layout: dict[str, slice] | None = None,
) -> tuple[Result, list[_Run]]:
    """The active-set loop of :func:`solve` from ``x0`` (laid out as ``layout``, default
    this program's); ``prior`` runs count in the Result's iterations and times. Returns the
    Result and every run so far."""
    opts = problem.collision_options
    active = ActiveSet.of(problem)
    joints0 = None  # the first start: q_init with its pressed self pairs parted
    if x0 is None and len(active.links):
        joints0 = separated_start(
            problem.robot,
            active.pm,
            active.links,
            opts.margin,
            problem.q_init,
            [c.patch.joint_id for c in problem.contacts],
        )
    base_key = (problem.key(), len(active.boxes), opts.self_collision, opts.exclude)
    learned_self, learned_env = _LEARNED.get(base_key, (frozenset(), frozenset()))
    active.self_pairs, active.env_pairs = set(learned_self), set(learned_env)
    cold = problem.solver_options
    problem.solver_options = _collision_solver_options(cold)
    loop = _Loop(problem, active, problem.solver_options, x0, joints0, layout)
    result: Result | None = None
    try:
        for _attempt in range(opts.tighten + 1):
            loop.rounds(opts.max_rounds)
            if len(active.self_pairs) + len(active.env_pairs) <= _LEARNED_MAX_PAIRS:
                _LEARNED[base_key] = (frozenset(active.self_pairs), frozenset(active.env_pairs))
            result = _result(problem, [*prior, *loop.runs], loop.margin)
            if result.success or loop.runs[-1].status not in _IPOPT_OK:
                return result, [*prior, *loop.runs]
            if not any(c.name.startswith("collision") for c in result.verification.failures):
                return result, [*prior, *loop.runs]
            loop.margin += 0.01  # the proxies passed but a mesh did not: tighten and retry
    finally:
        problem.solver_options = cold
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

    problem: Problem
    active: ActiveSet
    cold_run: SolverOptions
    x_warm: np.ndarray | None
    joints0: np.ndarray | None
    layout: dict[str, slice] | None = None  # the blocks of x_warm when not this program's
    runs: list[_Run] = dataclasses.field(default_factory=list)
    lam: dict[str, Any] | None = None
    margin: float = 0.0

    def __post_init__(self) -> None:
        self.margin = self.problem.collision_options.margin
        self.q_check = self.problem.q_init

    def rounds(self, max_rounds: int) -> None:
        """Up to ``max_rounds`` IPOPT runs, each after holding the pairs near (and violated
        at) the last posture; ends when no candidate pair outside the held ones is violated
        or a run fails."""
        problem, active = self.problem, self.active
        for _round in range(max_rounds):
            scan = active.scan(self.q_check, self.margin, near=not self.runs)
            if self.runs and not (scan.violated_self or scan.violated_env):
                return  # no candidate outside the active set is violated
            active.grow(scan)
            term = CollisionTerm(
                active.pm,
                tuple(sorted(active.self_pairs)),
                tuple(sorted(active.env_pairs)),
                active.boxes,
                self.margin,
            )
            problem.collision_term = term
            if self.lam is None:
                problem.solver_options = self.cold_run
                run = _run_ipopt(problem, self.x_warm, joints0=self.joints0, layout=self.layout)
            else:
                problem.solver_options = dataclasses.replace(self.cold_run, warm_start=True)
                lam = _map_collision_multipliers(self.lam, term)
                layout = self.runs[-1].compiled.x_index
                run = _run_ipopt(problem, self.x_warm, self.runs[-1].lam_x, lam, layout=layout)
            self.runs.append(run)
            if run.status not in _IPOPT_OK:
                return
            self.x_warm = run.x
            self.lam = _block_multipliers(run, term)
            self.q_check = configuration_from_x(problem, run.compiled, run.x)


def _result(problem: Problem, runs: list[_Run], margin: float | None = None) -> Result:
    """The Result of the last run (times and iterations summed over every run)."""
    run = runs[-1]
    outputs = _outputs(run)
    q = configuration_from_x(problem, run.compiled, run.x)
    torques = outputs["torques"]
    posture = posture_dict(problem, q, torques, outputs, margin)
    geometry = problem.robot.collision_model() if problem.collision_options is not None else None
    report = verify_posture(posture, problem.robot.model, geometry)
    status = run.status
    ipopt_ok = status in _IPOPT_OK
    success = ipopt_ok and report.ok
    if success:
        message = "verified"
    elif not ipopt_ok:
        message = f"IPOPT did not converge ({status})"
    else:
        message = "IPOPT converged but the re-check failed: " + "; ".join(
            f"{c.name} {c.value:.3g} > {c.tolerance:.1g}" + (f" ({c.detail})" if c.detail else "")
            for c in report.failures
        )
    iterations = sum(r.iterations for r in runs)
    solve_time = sum(r.solve_time_s for r in runs)
    posture.update(
        {
            "success": success,
            "status": status,
            "message": message,
            "iterations": iterations,
            "solve_time_s": solve_time,
            "ipopt_runs": len(runs),
            "max_violation": report.max_violation,
            "diagnosis": None,
            "checks": {
                c.name: {"value": c.value, "tolerance": c.tolerance, "ok": c.ok, "detail": c.detail}
                for c in report.checks
            },
            "notes": list(report.notes),
        }
    )
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
    )


def configuration_from_x(problem: Problem, compiled: Any, x: np.ndarray) -> np.ndarray:
    """Pinocchio q (nq,) from the solver's variables: R = R0·exp(w) computed exactly."""
    p = x[compiled.x_index["base.position"]]
    w = x[compiled.x_index["base.rotation"]]
    qj = x[compiled.x_index["joints"]]
    R0 = pin.Quaternion(problem.q_init[3:7]).normalized().matrix()
    quat = pin.Quaternion(R0 @ pin.exp3(w)).normalized().coeffs()  # (x, y, z, w)
    return np.concatenate([p, quat, qj])


def posture_dict(
    problem: Problem,
    q: np.ndarray,
    torques: np.ndarray,
    outputs: dict[str, np.ndarray],
    margin: float | None = None,
) -> dict[str, Any]:
    """The posture-file content (schema posturegen.posture/1) without the solver fields."""
    robot = problem.robot
    tasks = []
    for t in problem.tasks:
        tasks.append(
            {
                "type": "position",
                "frame": t.frame,
                "target": np.asarray(t.target).tolist(),
                "rotation": None if t.R_target is None else np.asarray(t.R_target).tolist(),
                "weight": t.weight,
            }
        )
    return {
        "schema": SCHEMA,
        "robot": robot.to_dict(),
        "q": q.tolist(),
        "joint_names": robot.joint_names,
        "torques": np.asarray(torques).tolist(),
        "gravity": np.array(robot.model.gravity.linear).tolist(),
        "contacts": [c.to_dict(outputs) for c in problem.contacts],
        "tasks": tasks,
        "obstacles": [o.to_dict() for o in problem.scene.obstacles],
        "surfaces": [s.to_dict() for s in problem.scene.surfaces.values()],
        "self_collision": problem.self_collision,
        "torque_limit_scale": problem.torque_limit_scale,
        "collision": _collision_dict(problem, margin),
    }


def _collision_dict(problem: Problem, margin: float | None) -> dict[str, Any] | None:
    """What the mesh check must test: the boxes, and the pairs it leaves unchecked with the
    reason of each (posturegen.pairs; verify recomputes all but the user's)."""
    opts = problem.collision_options
    if opts is None:
        return None
    robot = problem.robot
    model = robot.model
    unchecked: list[dict[str, Any]] = []
    if opts.self_collision:
        geometry = robot.collision_model()
        rule = pair_rule(model, geometry, str(robot.srdf) if robot.srdf else None)
        user = frozenset(excluded_joint_ids(robot, opts))
        unchecked = unchecked_entries(model, geometry, rule, user)
    return {
        "margin": opts.margin if margin is None else margin,
        "self": opts.self_collision,
        "unchecked": unchecked,
        "boxes": [b.to_dict(model) for b in env_boxes(problem)],
    }
