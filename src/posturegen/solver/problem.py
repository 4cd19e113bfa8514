"""The posture problem (paper eq. 1) as data, and what one IPOPT run solves of it.

A :class:`Problem` lists *terms* (the contacts, tasks, costs; the configuration and the static
equilibrium are added by :meth:`Program.terms`) and the initial posture. Building is separate
from solving: :func:`posturegen.solver.solve.solve` never writes on a Problem. What a solve
changes for one IPOPT run (the torque-limit scale of a continuation, the collision options, the
solver options, the active collision rows) is a :class:`Program`: the problem and those
overrides, a frozen value of the solve's own. The compiled program of a structure is cached by
:mod:`posturegen.solver.compile`."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._cache import Ref
from ..collision.boxes import CollisionOptions
from ..errors import InputError
from ..model.robot import Robot
from ..model.scene import Scene
from ..terms.configuration import ConfigurationTerm
from ..terms.contacts import Contact
from ..terms.elastic import Elastic
from ..terms.equilibrium import StaticEquilibrium
from ..terms.nlp import Term
from ..terms.tasks import Task
from . import codegen
from .compile import CompiledNLP, compile_program, constraint_counts, numeric, summary
from .qp import registry as qp_registry

# MUMPS' scalings off (IPOPT's defaults: 77 and 7, automatic). Measured 2026-12-03 with the
# same iterations on every planner family (talos-reach-balance-free 12 median, -collision 13,
# talos-stances-collision 3188 against 3189 on 150 problems) and about 17 % fewer
# instructions in IPOPT (callgrind, free family); the scripted climbs all verify, in 10,912
# iterations instead of 15,417 (ATLAS stairs 7929 -> 3682, HRP-2 vertical ladder 2089 -> 2530)
# the solvers a problem may ask for (SolverOptions.method)
METHODS = ("auto", "sqp", "ipopt")
# "auto": on postures never seen it verifies more than IPOPT alone, faster (2026-12-05,
# in-process after each family's first call, 4 collision families x seeds 7 and 11 x 49
# problems: 389 verified against 386, medians 14.9-25.0 ms against 16.9-31.1; the free
# reach 5.4 against 6.3 ms); a posture neither verifies pays both calls (the stances' max
# 521 against 271 ms). Sequences keep IPOPT (SEQUENCE_METHOD).
DEFAULT_METHOD = "auto"
# the solver of the shipped climbs and of plans, whose postures each start from the one
# before (an SQP solution is another local solution): under "auto" HRP-2's vertical ladder
# climb failed its stage "left foot on rung 2" (IPOPT: 17 of 17 stages) and ATLAS' 4-stair
# plan was not reached (27.5 s; IPOPT 10.9 s, 10 stages) (2026-12-05, warm)
SEQUENCE_METHOD = "ipopt"


def _env_method() -> str:
    """$POSTUREGEN_SOLVER, stripped ("" when unset)."""
    return os.environ.get("POSTUREGEN_SOLVER", "").strip()


def with_sequence_method(solver: dict[str, Any]) -> dict[str, Any]:
    """Solver options (a problem file's ``options.solver``) with SEQUENCE_METHOD, unless they
    or $POSTUREGEN_SOLVER already name a solver."""
    if "method" in solver or _env_method():
        return dict(solver)
    return {**solver, "method": SEQUENCE_METHOD}


MUMPS_SCALING = {"ipopt.mumps_scaling": 0, "ipopt.mumps_permuting_scaling": 0}


@dataclass(frozen=True)
class SolverOptions:
    """The solver's settings: which solver (``method``), and IPOPT's and the SQP's limits."""

    tol: float = 1e-8
    constr_viol_tol: float = 1e-9
    max_iter: int = 200
    max_cpu_time: float = 30.0
    print_level: int = 0
    # Generated C for the program's functions (posturegen.solver.codegen): "auto" compiles a
    # structure before its first solve and loads it from the disk cache in later sessions
    # ("sync": the same), "background" compiles while the virtual machine solves, "cached"
    # uses a library only when on disk, "off" keeps CasADi's virtual machine; None:
    # $POSTUREGEN_CODEGEN, else "auto". Without a C compiler: "off".
    codegen: str | None = None
    # the same as codegen="sync" (compile before the first solve; kept for problem files)
    jit: bool = False
    # start from given primal and dual values (active-set re-solves of collision avoidance)
    warm_start: bool = False
    # IPOPT's initial barrier parameter of a warm start (posturegen.solver.starts sets its
    # own for a start from a solved posture)
    warm_mu_init: float = 1e-5
    # IPOPT's initial barrier parameter and strategy (None: monotone from IPOPT's 0.1)
    mu_init: float | None = None
    mu_strategy: str = "monotone"
    # IPOPT's first Hessian regularization δ and its growth factor while the KKT matrix's
    # inertia is wrong (None: IPOPT's 1e-4 and 100)
    first_hessian_perturbation: float | None = None
    perturb_inc_fact_first: float | None = None
    # the whole call's iterations of each solver (every run of one solve: active-set rounds,
    # continuations; under "auto" the SQP and IPOPT each have it): a run may use only what
    # is left of its solver's (rounded up to 25), and once spent no run of it starts and the
    # call fails saying so; a planner's bound on a stance that cannot be held. None:
    # unbounded. Not part of the structure (two problems that differ only by it share their
    # compiled program; a run cut short builds a variant with a smaller max_iter).
    max_call_iter: int | None = field(default=None, compare=False)
    # which solver runs (posturegen.solver.runs): "sqp" (the SQP core, posturegen.solver.sqp),
    # "ipopt", or "auto": the SQP, then IPOPT from the same start when the SQP fails. None:
    # $POSTUREGEN_SOLVER, else DEFAULT_METHOD. Not part of the structure: both run on the same
    # compiled functions.
    method: str | None = field(default=None, compare=False)
    # the SQP's QP solver (posturegen.solver.qp.registry; None: daqp, else proxsuite)
    qp: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.method is not None and self.method not in METHODS:
            raise InputError(
                "options.solver.method",
                f"unknown solver {self.method!r}",
                f"use one of: {', '.join(METHODS)}",
            )
        if self.qp is not None and self.qp not in qp_registry.names():
            raise InputError(
                "options.solver.qp",
                f"unknown QP solver {self.qp!r}",
                f"use one of: {', '.join(qp_registry.names())}",
            )

    def solver_method(self) -> str:
        """The effective solver: ``method``, else $POSTUREGEN_SOLVER, else DEFAULT_METHOD."""
        if self.method is not None:
            return self.method
        env = _env_method()
        if not env:
            return DEFAULT_METHOD
        if env not in METHODS:
            raise InputError(
                "$POSTUREGEN_SOLVER", f"unknown solver {env!r}", f"use one of: {', '.join(METHODS)}"
            )
        return env

    def ipopt(self) -> dict[str, Any]:
        """The options dict passed to casadi.nlpsol."""
        opts: dict[str, Any] = {
            "ipopt.tol": self.tol,
            "ipopt.constr_viol_tol": self.constr_viol_tol,
            "ipopt.max_iter": self.max_iter,
            "ipopt.max_cpu_time": self.max_cpu_time,
            "ipopt.print_level": self.print_level,
            "ipopt.sb": "yes",
            # measured on the talos-stand-reach family: same success, 9 % faster than adaptive
            "ipopt.mu_strategy": self.mu_strategy,
            "ipopt.bound_relax_factor": 0.0,
            # MUMPS without its row/column scalings (MUMPS_SCALING): the factorization of our
            # small KKT systems (~160 rows) is mostly fixed cost, and the scalings are a good
            # part of it
            **MUMPS_SCALING,
            "print_time": False,
            "error_on_fail": False,
            # the parameters' multipliers are never read (and the collision slots' link and row
            # indices, parameters that pick, have none)
            "calc_lam_p": False,
        }
        if self.mu_init is not None:
            opts["ipopt.mu_init"] = self.mu_init
        if self.first_hessian_perturbation is not None:
            opts["ipopt.first_hessian_perturbation"] = self.first_hessian_perturbation
        if self.perturb_inc_fact_first is not None:
            opts["ipopt.perturb_inc_fact_first"] = self.perturb_inc_fact_first
        if self.warm_start:
            opts.update(
                {
                    "ipopt.warm_start_init_point": "yes",
                    "ipopt.mu_init": self.warm_mu_init,
                    "ipopt.warm_start_bound_push": 1e-6,
                    "ipopt.warm_start_bound_frac": 1e-6,
                    "ipopt.warm_start_slack_bound_push": 1e-6,
                    "ipopt.warm_start_slack_bound_frac": 1e-6,
                    "ipopt.warm_start_mult_bound_push": 1e-6,
                }
            )
        return opts

    def codegen_mode(self) -> str:
        """The effective generated-C mode (see :mod:`posturegen.solver.codegen`)."""
        return codegen.resolve_mode("sync" if self.jit else self.codegen)


@dataclass
class Problem:
    """A posture problem: robot, scene, terms and the initial posture.

    Build it with :func:`posturegen.io.problem_file.problem_from_dict` or by hand; inspect it with
    :meth:`summary`; solve it with :func:`posturegen.solver.solve.solve` (which never writes on
    it: one Problem can be solved from several threads at once).
    """

    robot: Robot
    scene: Scene
    contacts: list[Contact]
    tasks: list[Term]
    costs: list[Term]
    q_init: np.ndarray  # (nq,) initial posture: warm start and posture-cost reference
    self_collision: bool = False
    torque_limit_scale: float = 1.0  # |τ_j| <= scale·effort_j
    solver_options: SolverOptions = field(default_factory=SolverOptions)
    collision_options: CollisionOptions | None = None  # None: no avoidance
    # [m] CoP margin of force-bearing contacts made from this problem's (posturegen.climb.stance);
    # None: posturegen.terms.cop.DEFAULT_COP_MARGIN
    cop_margin: float | None = None
    # hard rows relaxed by L1-penalized slacks (posturegen.terms.elastic; the diagnosis of a
    # failure solves a copy of the problem with it); None: the real program
    elastic: Elastic | None = None

    def __post_init__(self) -> None:
        """Tasks built in Python are numbered by their place (their names and blocks, and
        their errors' field names, read ``tasks[i]``) and their frames and joints checked."""
        tasks = list(self.tasks)
        for i, t in enumerate(tasks):
            if isinstance(t, Task) and t.index != i:
                tasks[i] = dataclasses.replace(t, index=i)
            if isinstance(t, Task):
                t.check_robot(self.robot, f"tasks[{i}]")
        self.tasks = tasks

    def terms(self) -> list[Term]:
        """Every term in declaration order (without collision rows: a solve adds them)."""
        return Program.of(self).terms()

    def key(self) -> tuple[Any, ...]:
        """The structure key: robot, each term's key, the elastic relaxation, solver options."""
        return Program.of(self).key()

    def compile(self) -> CompiledNLP:
        """The compiled program of this structure and solver options (cached)."""
        return Program.of(self).compile()

    def numeric(
        self, compiled: CompiledNLP
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x0, p, lbg, ubg) of this instance for a compiled structure."""
        return numeric(Program.of(self), compiled)

    def summary(self) -> str:
        """Human-readable sizes of the program: variable and constraint blocks, cost terms
        (no collision rows; :func:`posturegen.solver.inspection.describe` adds those a solve
        starts with)."""
        return summary(Program.of(self))

    def constraint_counts(self) -> dict[str, int]:
        """Rows per constraint block."""
        return constraint_counts(Program.of(self))


@dataclass(frozen=True, eq=False)
class Program:
    """What one IPOPT run solves: ``problem`` with the solve's overrides (solver options,
    torque-limit scale, collision options) and its active collision rows. The terms read the
    instance through it (:class:`posturegen.terms.nlp.Instance`)."""

    problem: Problem
    solver_options: SolverOptions
    torque_limit_scale: float
    collision_options: CollisionOptions | None
    collision_term: Term | None = None

    @classmethod
    def of(cls, problem: Problem, **overrides: Any) -> Program:
        """The problem as it is, with ``overrides`` of the fields above."""
        program = cls(
            problem, problem.solver_options, problem.torque_limit_scale, problem.collision_options
        )
        return dataclasses.replace(program, **overrides) if overrides else program

    def but(self, **overrides: Any) -> Program:
        """This program with other overrides."""
        return dataclasses.replace(self, **overrides)

    @property
    def robot(self) -> Robot:
        return self.problem.robot

    @property
    def scene(self) -> Scene:
        return self.problem.scene

    @property
    def contacts(self) -> list[Contact]:
        return self.problem.contacts

    @property
    def tasks(self) -> list[Term]:
        return self.problem.tasks

    @property
    def q_init(self) -> np.ndarray:
        return self.problem.q_init

    @property
    def costs(self) -> list[Term]:
        return self.problem.costs

    @property
    def self_collision(self) -> bool:
        return self.problem.self_collision

    @property
    def elastic(self) -> Elastic | None:
        return self.problem.elastic

    def terms(self) -> list[Term]:
        """Every term in declaration order."""
        extra = [self.collision_term] if self.collision_term is not None else []
        return [
            ConfigurationTerm(),
            *self.problem.contacts,
            *self.problem.tasks,
            *extra,
            StaticEquilibrium(),
            *self.problem.costs,
        ]

    def key(self) -> tuple[Any, ...]:
        """The structure key: the robot's model (held, :class:`posturegen._cache.Ref`), each
        term's key, the elastic relaxation, the solver options."""
        return (
            Ref(self.robot.model),
            tuple(t.key() for t in self.terms()),
            self.elastic,
            self.solver_options,
        )

    def compile(self) -> CompiledNLP:
        """The compiled program of this structure and solver options (cached)."""
        return compile_program(self)

    def numeric(
        self, compiled: CompiledNLP
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x0, p, lbg, ubg) of this instance for a compiled structure."""
        return numeric(self, compiled)

    def summary(self) -> str:
        """Human-readable sizes of the program (with its collision rows)."""
        return summary(self)
