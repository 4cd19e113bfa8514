"""The posture problem (paper eq. 1) as a CasADi nonlinear program.

Building is separate from solving. A :class:`Problem` lists *terms* (the configuration, contacts,
tasks, the static equilibrium, costs). Each term declares its symbolic variables, parameters,
constraints and costs once per problem *structure* (:meth:`Term.key`), and gives the numeric
parameter values and initial guess of one instance. The compiled program is cached by structure,
so a second problem of the same shape (other targets, other contact poses) pays no set-up.
"""

from __future__ import annotations

import collections
import functools
import hashlib
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import SolveError
from ..model.kinematics import CasadiKinematics, KinematicState, so3_exp
from ..model.robot import Robot
from ..model.scene import Scene
from ..terms.elastic import Elastic, soften

ArrayLike = np.ndarray | float


@dataclass(frozen=True)
class BlockDerivatives:
    """Hand-built derivatives of a constraint block g_b that depends on the variables only
    through z (nz,), a vector of them: ``jacobian`` (rows, nz) = ∂g_b/∂z and ``hessian``
    (nz, nz) = ∇²_z(λᵀg_b) as an expression of the symbols ``lam`` (rows,). The program uses
    them in place of CasADi's automatic derivatives of the block (tested equal to them)."""

    z: ca.SX
    jacobian: ca.SX
    lam: ca.SX
    hessian: ca.SX


class NLP:
    """Symbolic pieces of one program: x (variables), p (parameters), g (constraints), cost."""

    def __init__(self) -> None:
        self.x: dict[str, tuple[ca.SX, np.ndarray, np.ndarray]] = {}
        self.p: dict[str, ca.SX] = {}
        self.g: dict[str, tuple[ca.SX, np.ndarray, np.ndarray]] = {}
        # a block's own derivatives, or the function that builds them when they are needed
        self.derivatives: dict[str, BlockDerivatives | Callable[[], BlockDerivatives]] = {}
        self.costs: dict[str, ca.SX] = {}
        self.outputs: dict[str, ca.SX] = {}

    def variable(self, name: str, n: int, lb: ArrayLike = -np.inf, ub: ArrayLike = np.inf) -> ca.SX:
        """Declare n variables with (constant) bounds."""
        if name in self.x:
            raise SolveError(f"variable block '{name}' declared twice")
        sym = ca.SX.sym(name, n)
        self.x[name] = (
            sym,
            np.broadcast_to(lb, (n,)).astype(float),
            np.broadcast_to(ub, (n,)).astype(float),
        )
        return sym

    def parameter(self, name: str, n: int) -> ca.SX:
        """Declare n parameters, given numerically at each solve."""
        if name in self.p:
            raise SolveError(f"parameter block '{name}' declared twice")
        self.p[name] = ca.SX.sym(name, n)
        return self.p[name]

    def constrain(
        self,
        name: str,
        expr: ca.SX,
        lb: ArrayLike,
        ub: ArrayLike,
        derivatives: BlockDerivatives | Callable[[], BlockDerivatives] | None = None,
    ) -> None:
        """lb <= expr <= ub (use lb == ub for equalities); ``derivatives``: the block's own
        Jacobian and Hessian (see :class:`BlockDerivatives`), or a function that builds them
        (called only when a solver is built from the expressions)."""
        if name in self.g:
            raise SolveError(f"constraint block '{name}' declared twice")
        expr = ca.vec(ca.SX(expr))
        n = expr.shape[0]
        if derivatives is not None:
            if isinstance(derivatives, BlockDerivatives):
                _check_derivatives(name, derivatives, n)
            self.derivatives[name] = derivatives
        self.g[name] = (
            expr,
            np.broadcast_to(lb, (n,)).astype(float),
            np.broadcast_to(ub, (n,)).astype(float),
        )

    def minimize(self, name: str, expr: ca.SX) -> None:
        """Add a scalar term to the cost."""
        self.costs[name] = self.costs.get(name, 0) + expr

    def output(self, name: str, expr: ca.SX) -> None:
        """An expression evaluated at the solution (torques, world points...)."""
        self.outputs[name] = ca.vec(ca.SX(expr))


@dataclass
class BuildContext:
    """What terms share while declaring: the robot, its symbolic state, contact forces."""

    robot: Robot
    nlp: NLP
    kin: CasadiKinematics
    state: KinematicState | None = None
    base_position: ca.SX | None = None  # (3,)
    base_rotation: ca.SX | None = None  # (3,) w of R_base = R0·exp([w]×)
    joints: ca.SX | None = None  # (nj,)
    # (joint id, world point (3,), world force on the robot (3,)) of every force-bearing point
    force_points: list[tuple[int, ca.SX, ca.SX]] = field(default_factory=list)
    torques: ca.SX | None = None  # (nj,) actuated joint torques, set by the equilibrium


class Term(ABC):
    """Something that adds variables, constraints or costs to the posture problem."""

    name: str

    @abstractmethod
    def key(self) -> tuple[Any, ...]:
        """Everything that changes the program's structure (not its parameter values)."""

    @abstractmethod
    def declare(self, ctx: BuildContext) -> None:
        """Add symbolic variables, parameters, constraints and costs to ``ctx.nlp``."""

    def parameters(self, problem: Problem) -> dict[str, np.ndarray]:
        """Numeric values of the parameters this term declared."""
        return {}

    def initial_guess(self, problem: Problem) -> dict[str, np.ndarray]:
        """Initial values of the variables this term declared (zero when absent)."""
        return {}

    def bounds(self, problem: Problem) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        """Per-instance (lb, ub) of constraint blocks, overriding the declared ones."""
        return {}


@dataclass(frozen=True)
class SolverOptions:
    """IPOPT settings."""

    tol: float = 1e-8
    constr_viol_tol: float = 1e-9
    max_iter: int = 200
    max_cpu_time: float = 30.0
    print_level: int = 0
    # Generated C for the program's functions (posturegen.solver.codegen): "auto" compiles a
    # structure
    # in the background once it is reused and loads it from the disk cache in later sessions,
    # "sync" compiles before the first solve, "off" keeps CasADi's virtual machine; None:
    # $POSTUREGEN_CODEGEN, else "auto". Without a C compiler: "off".
    codegen: str | None = None
    # the same as codegen="sync" (compile before the first solve; kept for problem files)
    jit: bool = False
    # start from given primal and dual values (active-set re-solves of collision avoidance)
    warm_start: bool = False
    # IPOPT's initial barrier parameter and strategy (None: monotone from IPOPT's 0.1)
    mu_init: float | None = None
    mu_strategy: str = "monotone"
    # IPOPT's first Hessian regularization δ and its growth factor while the KKT matrix's
    # inertia is wrong (None: IPOPT's 1e-4 and 100)
    first_hessian_perturbation: float | None = None
    perturb_inc_fact_first: float | None = None

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
            "print_time": False,
            "error_on_fail": False,
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
                    "ipopt.mu_init": 1e-5,
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
        from . import codegen

        return codegen.resolve_mode("sync" if self.jit else self.codegen)


@dataclass
class _Layout:
    """Where each named block sits in x, p and g, the cost terms' names, and the bounds."""

    x_index: dict[str, slice]
    p_index: dict[str, slice]
    g_index: dict[str, slice]
    cost_names: list[str]
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray

    @property
    def n_x(self) -> int:
        """Number of variables."""
        return self.lbx.size

    @property
    def n_g(self) -> int:
        """Number of constraint rows."""
        return self.lbg.size


@dataclass
class CompiledNLP(_Layout):
    """A built solver with the layout of its x, p and g vectors.

    ``solver`` runs CasADi's virtual machine until the structure's generated C is available
    (``library``: then it runs the compiled library of ``library_key``, see
    :mod:`posturegen.solver.codegen`); :meth:`refresh` switches when the library appears."""

    key: tuple[Any, ...]
    solver: ca.Function
    nlp: ca.Function  # (x, p) -> (f, g): the program itself, for inspection and tests
    outputs: ca.Function  # (x, p) -> outputs
    build_time_s: float
    ipopt_options: dict[str, Any] = field(default_factory=dict)
    codegen_mode: str = "off"
    library_key: str | None = None  # content hash of the program (None: codegen off)
    library: bool = False  # solver runs the compiled library
    uses: int = 0  # solves of this structure in this process

    def refresh(self) -> None:
        """Count a use of the solver; switch to the compiled library when it is in the cache;
        in mode ``auto``, start its background build at the second use."""
        self.uses += 1
        if self.library or self.library_key is None:
            return
        from . import codegen

        solver = codegen.load(self.library_key, self.ipopt_options)
        if solver is not None:
            self.solver, self.library = solver, True
        elif self.codegen_mode == "auto" and self.uses >= codegen.AUTO_BUILD_AFTER_USES:
            codegen.build_in_background(self.library_key, self.solver, self.nlp)


def _layout(blocks: dict[str, Any], size: Any) -> dict[str, slice]:
    out, k = {}, 0
    for name, item in blocks.items():
        n = size(item)
        out[name] = slice(k, k + n)
        k += n
    return out


@dataclass
class _Program(_Layout):
    """The symbolic program of one structure: min f(x, p) s.t. lbg <= g(x, p) <= ubg,
    lbx <= x <= ubx, with the layout of x, p and g, shared by its solver-option variants."""

    x: ca.SX
    p: ca.SX
    f: ca.SX
    g: ca.SX
    function: ca.Function  # (x, p) -> (f, g)
    outputs: ca.Function  # (x, p) -> outputs and cost terms
    # the declared pieces, kept for derivative_functions (built on first use)
    declared: NLP | None = None
    _derivatives: dict[str, ca.Function] | None = field(default=None, repr=False)

    @property
    def derivative_functions(self) -> dict[str, ca.Function]:
        """nlpsol's "jac_g" and "hess_lag" when some block has hand-built derivatives, else
        empty; built only when a solver is built from the expressions (a library loaded from
        the disk cache has them compiled: Talos near-body, 110 ms saved per structure)."""
        if self._derivatives is None:
            has = self.declared is not None and bool(self.declared.derivatives)
            self._derivatives = (
                _derivative_functions(self.declared, self.x, self.p, self.f, self.g, self.g_index)
                if has
                else {}
            )
        return self._derivatives

    @property
    def derivative_key(self) -> str:
        """What the library key adds for hand-built derivatives: the source of the package
        (the code that writes them), so that any change to it builds the library again; ""
        without them. Cheaper than serializing the derivative functions (140 ms)."""
        has = self.declared is not None and bool(self.declared.derivatives)
        return _source_digest() if has else ""


_CACHE: collections.OrderedDict[tuple[Any, ...], CompiledNLP] = collections.OrderedDict()
_PROGRAMS: collections.OrderedDict[tuple[Any, ...], _Program] = collections.OrderedDict()
_CACHE_SIZE = 32


@dataclass
class Problem:
    """A posture problem: robot, scene, terms and the initial posture.

    Build it with :func:`posturegen.io.problem_file.problem_from_dict` or by hand; inspect it with
    :meth:`summary`; solve it with :func:`posturegen.solver.solve.solve`.
    """

    robot: Robot
    scene: Scene
    contacts: list[Any]  # posturegen.terms.contacts.Contact
    tasks: list[Term]
    costs: list[Term]
    q_init: np.ndarray  # (nq,) initial posture: warm start and posture-cost reference
    self_collision: bool = False
    torque_limit_scale: float = 1.0  # |τ_j| <= scale·effort_j
    solver_options: SolverOptions = field(default_factory=SolverOptions)
    collision_options: Any = None  # posturegen.collision.rows.CollisionOptions; None: no avoidance
    # [m] CoP margin of force-bearing contacts made from this problem's (posturegen.climb.stance);
    # None: posturegen.terms.cop.DEFAULT_COP_MARGIN
    cop_margin: float | None = None
    # the active collision rows of the current solve (set by posturegen.solver.solve)
    collision_term: Term | None = None
    # hard rows relaxed by L1-penalized slacks (posturegen.terms.elastic; the diagnosis of a
    # failure solves a copy of the problem with it); None: the real program
    elastic: Elastic | None = None

    def terms(self) -> list[Term]:
        """Every term in declaration order."""
        from ..terms.constraints import ConfigurationTerm, StaticEquilibrium

        extra = [self.collision_term] if self.collision_term is not None else []
        return [
            ConfigurationTerm(),
            *self.contacts,
            *self.tasks,
            *extra,
            StaticEquilibrium(),
            *self.costs,
        ]

    def key(self) -> tuple[Any, ...]:
        """The structure key: robot, each term's key, the elastic relaxation, solver options."""
        return (
            id(self.robot.model),
            tuple(t.key() for t in self.terms()),
            self.elastic,
            self.solver_options,
        )

    def compile(self) -> CompiledNLP:
        """The compiled program for this structure and these solver options (built once, then
        cached; the symbolic program is shared by every solver-option variant)."""
        key = self.key()
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
        import time

        from . import codegen

        t0 = time.perf_counter()
        prog = self._program()
        opts = self.solver_options.ipopt()
        mode = self.solver_options.codegen_mode()
        lib_key = codegen.library_key(prog.function, prog.derivative_key) if mode != "off" else None
        # the structure's library from the disk cache: no SX derivatives to build
        solver = codegen.load(lib_key, opts) if lib_key is not None else None
        library = solver is not None
        if solver is None:
            solver = ca.nlpsol(
                "posture",
                "ipopt",
                {"x": prog.x, "p": prog.p, "f": prog.f, "g": prog.g},
                {**opts, **prog.derivative_functions},
            )
            if mode == "sync" and lib_key is not None:
                codegen.build(lib_key, solver, prog.function)
                built = codegen.load(lib_key, opts)
                if built is not None:
                    solver, library = built, True
        compiled = CompiledNLP(
            key=key,
            solver=solver,
            nlp=prog.function,
            outputs=prog.outputs,
            **{f.name: getattr(prog, f.name) for f in fields(_Layout)},
            build_time_s=time.perf_counter() - t0,
            ipopt_options=opts,
            codegen_mode=mode,
            library_key=lib_key,
            library=library,
        )
        _CACHE[key] = compiled
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
        return compiled

    def _program(self) -> _Program:
        """The symbolic program of this structure (declared once, then cached)."""
        key = self.key()[:3]
        if key in _PROGRAMS:
            _PROGRAMS.move_to_end(key)
            return _PROGRAMS[key]
        nlp = NLP()
        ctx = BuildContext(robot=self.robot, nlp=nlp, kin=self.robot.kinematics)
        for term in self.terms():
            term.declare(ctx)
        if self.elastic is not None:
            soften(nlp, self.elastic)
        x = ca.vertcat(*[v[0] for v in nlp.x.values()])
        p = ca.vertcat(*nlp.p.values()) if nlp.p else ca.SX(0, 1)
        g = ca.vertcat(*[v[0] for v in nlp.g.values()])
        cost = sum(nlp.costs.values()) if nlp.costs else ca.SX(0)
        names = list(nlp.outputs)
        prog = _Program(
            x=x,
            p=p,
            f=cost,
            g=g,
            function=ca.Function("nlp", [x, p], [cost, g], ["x", "p"], ["f", "g"]),
            outputs=ca.Function(
                "outputs",
                [x, p],
                [nlp.outputs[n] for n in names] + [nlp.costs[n] for n in nlp.costs],
                ["x", "p"],
                names + [f"cost.{n}" for n in nlp.costs],
            ),
            x_index=_layout(nlp.x, lambda v: v[0].shape[0]),
            p_index=_layout(nlp.p, lambda v: v.shape[0]),
            g_index=_layout(nlp.g, lambda v: v[0].shape[0]),
            cost_names=list(nlp.costs),
            lbx=np.concatenate([v[1] for v in nlp.x.values()]),
            ubx=np.concatenate([v[2] for v in nlp.x.values()]),
            lbg=np.concatenate([v[1] for v in nlp.g.values()]),
            ubg=np.concatenate([v[2] for v in nlp.g.values()]),
            declared=nlp,
        )
        _PROGRAMS[key] = prog
        while len(_PROGRAMS) > _CACHE_SIZE:
            _PROGRAMS.popitem(last=False)
        return prog

    def numeric(
        self, compiled: CompiledNLP
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x0, p, lbg, ubg) of this instance for a compiled structure."""
        x0 = np.zeros(compiled.n_x)
        p = np.zeros(sum(s.stop - s.start for s in compiled.p_index.values()))
        lbg, ubg = compiled.lbg.copy(), compiled.ubg.copy()
        for term in self.terms():
            for name, value in term.parameters(self).items():
                p[compiled.p_index[name]] = np.ravel(value, order="F")
            for name, value in term.initial_guess(self).items():
                x0[compiled.x_index[name]] = np.ravel(value, order="F")
            for name, (lb, ub) in term.bounds(self).items():
                lbg[compiled.g_index[name]] = lb
                ubg[compiled.g_index[name]] = ub
        return x0, p, lbg, ubg

    def summary(self) -> str:
        """Human-readable sizes of the program: variable and constraint blocks, cost terms
        (collision rows: those of ``collision_term``, see
        :func:`posturegen.solver.inspection.describe`
        for the rows a solve starts with)."""
        c = self._program()
        lines = [
            f"robot {self.robot.name}: nq={self.robot.model.nq}, nv={self.robot.model.nv}",
            f"variables: {c.n_x}",
        ]
        lines += [f"  {n}: {s.stop - s.start}" for n, s in c.x_index.items()]
        lines.append(f"constraints: {c.n_g}")
        lines += [f"  {n}: {s.stop - s.start}" for n, s in c.g_index.items()]
        lines.append("costs: " + ", ".join(c.cost_names))
        return "\n".join(lines)

    def constraint_counts(self) -> dict[str, int]:
        """Rows per constraint block."""
        c = self._program()
        return {n: s.stop - s.start for n, s in c.g_index.items()}


@functools.cache
def _source_digest() -> str:
    """SHA-256 (16 hex digits) of the package's Python sources."""
    h = hashlib.sha256()
    for path in sorted(Path(__file__).parent.glob("*.py")):
        h.update(path.name.encode() + path.read_bytes())
    return h.hexdigest()[:16]


def _derivative_functions(
    nlp: NLP, x: ca.SX, p: ca.SX, cost: ca.SX, g: ca.SX, index: dict[str, slice]
) -> dict[str, ca.Function]:
    """nlpsol's ``jac_g`` and ``hess_lag`` for a program with hand-built block derivatives:
    CasADi's automatic derivatives of every other block (one Jacobian and one Hessian, so that
    they share their subexpressions) plus each block's own, placed at the columns of its z."""
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
    own = [np.arange(index[n].start, index[n].stop) for n in nlp.derivatives]
    rest = np.setdiff1d(np.arange(g.shape[0]), np.concatenate(own)).tolist()
    jac_rest = ca.jacobian(g[rest], x)
    H = ca.hessian(lam_f * cost + ca.dot(lam_g[rest], g[rest]), x)[0]
    rows: dict[int, ca.SX] = {int(r): jac_rest[k, :] for k, r in enumerate(rest)}
    for name, given in nlp.derivatives.items():
        sl = index[name]
        d = given if isinstance(given, BlockDerivatives) else given()
        _check_derivatives(name, d, sl.stop - sl.start)
        cols = _columns(d.z, x)
        J = ca.SX(sl.stop - sl.start, x.shape[0])
        J[:, cols] = d.jacobian
        for k in range(sl.stop - sl.start):
            rows[sl.start + k] = J[k, :]
        Hb = ca.SX(x.shape[0], x.shape[0])
        Hb[cols, cols] = ca.substitute(d.hessian, d.lam, lam_g[sl])
        H = H + Hb
    jac = ca.vertcat(*[rows[r] for r in range(g.shape[0])])
    return {
        "jac_g": ca.Function("nlp_jac_g", [x, p], [g, jac], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function(
            "nlp_hess_l",
            [x, p, lam_f, lam_g],
            [ca.triu(H)],
            ["x", "p", "lam_f", "lam_g"],
            ["triu_hess_gamma_x_x"],
        ),
    }


def _check_derivatives(name: str, d: BlockDerivatives, rows: int) -> None:
    if d.jacobian.shape != (rows, d.z.shape[0]):
        raise SolveError(f"constraint block '{name}': Jacobian of the wrong shape")


def _columns(z: ca.SX, x: ca.SX) -> list[int]:
    """Where each symbol of z sits in x (∂z/∂x is a selection matrix)."""
    if not all(z[k].is_symbolic() for k in range(z.shape[0])):
        raise SolveError("a block's derivatives must be taken w.r.t. variables of the program")
    rows, cols = ca.jacobian(z, x).sparsity().get_triplet()
    if sorted(rows) != list(range(z.shape[0])):
        raise SolveError("a block's derivatives are taken w.r.t. symbols that are not variables")
    return [c for _, c in sorted(zip(rows, cols, strict=True))]


def base_rotation(R0: ca.SX, w: ca.SX) -> ca.SX:
    """Base orientation R = R0 · exp([w]×): a local exponential map around the initial one."""
    return R0 @ so3_exp(w)
