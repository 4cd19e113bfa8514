"""Compiling a program: the symbolic program of a problem *structure* (declared once by its
terms), its IPOPT solver and the layout of its x, p and g vectors, each cached by structure.

A second problem of the same shape (other targets, other contact poses) pays no set-up: the
numeric parameter values, initial guess and bounds of an instance are filled by
:func:`numeric`. The caches key on :meth:`Compilable.key`, which holds the robot's model
(:class:`posturegen._cache.Ref`), so that an entry never outlives what it was built for."""

from __future__ import annotations

import collections
import json
import threading
import time
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple, Protocol

import casadi as ca
import numpy as np

from .._cache import BoundedCache
from ..collision import native
from ..errors import SolveError
from ..model.robot import Robot
from ..terms.elastic import Elastic, soften
from ..terms.nlp import NLP, BlockDerivatives, BuildContext, Term, check_derivatives
from . import codegen
from .fingerprint import source_digest, structure_fingerprint


class Compilable(Protocol):
    """What is compiled: a problem with a solve's overrides
    (:class:`posturegen.solver.problem.Program`)."""

    @property
    def robot(self) -> Robot: ...
    @property
    def solver_options(self) -> Any: ...
    @property
    def elastic(self) -> Elastic | None: ...
    def key(self) -> tuple[Any, ...]: ...
    def terms(self) -> list[Term]: ...


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
    kernels_epoch: int | None = None  # as _Program's: built again once it is stale
    uses: int = 0  # solves of this structure in this process
    # one IPOPT run of this solver at a time: its stats() are those of the last call
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def refresh(self) -> None:
        """Count a use of the solver; switch to the compiled library when it is in the cache;
        in mode ``background``, start its background build (at the first use)."""
        self.uses += 1
        if self.library or self.library_key is None:
            return
        solver = codegen.load(self.library_key, self.ipopt_options)
        if solver is not None:
            self.solver, self.library = solver, True
        elif self.codegen_mode == "background" and self.uses >= codegen.BACKGROUND_AFTER_USES:
            codegen.build_in_background(self.library_key, self.sources())

    def sources(self) -> codegen.Sources:
        """What this structure's library is generated from."""
        return codegen.Sources(self.solver, self.nlp, self.outputs, _layout_arrays(self))


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
    # the kernels' epoch (posturegen.collision.native.epoch) when they were wanted in machine
    # code but still being compiled: declared again once it has changed (None: nothing waits)
    kernels_epoch: int | None = None
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
        return source_digest() if has else ""


CACHE_SIZE = 32
# the leading items of Program.key() that are its structure (robot, terms, elastic form); the
# last is the solver options, each variant of them a solver of its own on the same functions
STRUCTURE_KEY = 3
# compiled solvers by structure and solver options; symbolic programs, layouts read from the
# disk cache and fingerprints ("": none) by structure
_CACHE: BoundedCache[CompiledNLP] = BoundedCache("compiled solvers", CACHE_SIZE)
_PROGRAMS: BoundedCache[_Program] = BoundedCache("symbolic programs", CACHE_SIZE)
_LAYOUTS: BoundedCache[_Layout] = BoundedCache("layouts from the disk cache", CACHE_SIZE)
_FINGERPRINTS: BoundedCache[str] = BoundedCache("structure fingerprints", 4 * CACHE_SIZE)


# how many program structures (robot, terms' keys, elastic relaxation) this process has made
# ready to solve, by how: "declared" (its symbolic program built) or "loaded" (its layout read
# from beside its library on disk, found by its fingerprint); a solver-option variant of a
# structure already made is neither
MADE: collections.Counter[str] = collections.Counter()


def is_compiled(program: Compilable) -> bool:
    """Whether the solver of this structure and these options is in the cache."""
    return program.key() in _CACHE


def compile_program(program: Compilable) -> CompiledNLP:
    """The compiled program for this structure and these solver options (built once, then
    cached; the symbolic program is shared by every solver-option variant)."""
    key = program.key()
    cached = _CACHE.get(key)
    if cached is not None and not _stale(cached.kernels_epoch):
        return cached
    t0 = time.perf_counter()
    opts = program.solver_options.ipopt()
    mode = program.solver_options.codegen_mode()
    lib_key = _structure_key(program) if mode != "off" else None
    # found by its fingerprint: solved from its library, without its symbolic program
    found = _from_disk(program, lib_key, opts) if lib_key is not None else None
    built = found or _from_expressions(program, lib_key, opts, mode)
    layout = built.layout
    compiled = CompiledNLP(
        key=key,
        solver=built.solver,
        nlp=built.nlp,
        outputs=built.outputs,
        **{f.name: getattr(layout, f.name) for f in fields(_Layout)},
        build_time_s=time.perf_counter() - t0,
        ipopt_options=opts,
        codegen_mode=mode,
        library_key=built.library_key,
        library=built.library,
        kernels_epoch=None if built.library else getattr(layout, "kernels_epoch", None),
    )
    return _CACHE.put(key, compiled)


def _structure_key(program: Compilable) -> str | None:
    """The library key of the structure's fingerprint (None: it has none)."""
    fingerprint = _FINGERPRINTS.get_or_make(
        program.key()[:STRUCTURE_KEY], lambda: structure_fingerprint(program) or ""
    )
    return codegen.structure_key(fingerprint) if fingerprint else None


class _Built(NamedTuple):
    """A structure's solver (on its library or on the expressions), its program (x, p) ->
    (f, g), its outputs and its layout."""

    solver: ca.Function
    nlp: ca.Function
    outputs: ca.Function
    layout: _Layout
    library: bool
    library_key: str | None


def _from_disk(program: Compilable, lib_key: str, opts: dict[str, Any]) -> _Built | None:
    """IPOPT on the library of ``lib_key``, its program and outputs, and its layout; None
    unless all are on disk and agree in size."""
    layout = _disk_layout(program, lib_key)
    functions = codegen.program_functions(lib_key) if layout is not None else None
    solver = codegen.load(lib_key, opts) if functions is not None else None
    if layout is None or functions is None or solver is None or not _agree(solver, layout):
        return None
    return _Built(solver, *functions, layout, True, lib_key)


def _from_expressions(
    program: Compilable, lib_key: str | None, opts: dict[str, Any], mode: str
) -> _Built:
    """The structure's symbolic program (declared and cached) and its solver: on its library
    when the disk cache has it (by ``lib_key``, else by the program's content), else on the
    expressions (in mode ``sync``, its library built first)."""
    prog = symbolic(program)
    if mode != "off" and lib_key is None:
        lib_key = codegen.library_key(prog.function, prog.derivative_key)
    # the structure's library from the disk cache: no SX derivatives to build
    solver = codegen.load(lib_key, opts) if lib_key is not None else None
    if solver is not None and _agree(solver, prog):
        return _on_library(solver, prog, lib_key)
    solver = ca.nlpsol(
        "posture",
        "ipopt",
        {"x": prog.x, "p": prog.p, "f": prog.f, "g": prog.g},
        {**opts, **prog.derivative_functions},
    )
    if mode in ("auto", "sync") and lib_key is not None:
        what = codegen.Sources(solver, prog.function, prog.outputs, _layout_arrays(prog))
        codegen.build(lib_key, what)
        built = codegen.load(lib_key, opts)
        if built is not None and _agree(built, prog):
            return _on_library(built, prog, lib_key)
    return _Built(solver, prog.function, prog.outputs, prog, False, lib_key)


def _on_library(solver: ca.Function, prog: _Program, lib_key: str) -> _Built:
    """IPOPT on the library of ``lib_key`` with the program and outputs compiled there too
    (the expressions' on CasADi's virtual machine took 1.6 ms of each Talos near-body call's
    re-check); the expressions' when the library lacks them."""
    functions = codegen.program_functions(lib_key)
    nlp, outputs = functions if functions is not None else (prog.function, prog.outputs)
    return _Built(solver, nlp, outputs, prog, True, lib_key)


def _agree(solver: ca.Function, layout: _Layout) -> bool:
    """Whether a solver's x, p and g have the layout's sizes."""
    n_p = sum(s.stop - s.start for s in layout.p_index.values())
    return (solver.size1_in("x0"), solver.size1_in("p"), solver.size1_out("g")) == (
        layout.n_x,
        n_p,
        layout.n_g,
    )


def layout_of(program: Compilable) -> _Layout:
    """The layout of the program's structure: from this process's caches, else from beside
    its library on disk, else from its symbolic program (declared and cached)."""
    found = _PROGRAMS.get(_program_key(program)) or _LAYOUTS.get(program.key()[:STRUCTURE_KEY])
    if found is not None:
        return found
    if program.solver_options.codegen_mode() != "off":
        lib_key = _structure_key(program)
        layout = _disk_layout(program, lib_key) if lib_key is not None else None
        if layout is not None:
            return layout
    return symbolic(program)


def _disk_layout(program: Compilable, lib_key: str) -> _Layout | None:
    """The layout saved beside the library of ``lib_key``, read once per process (then
    cached by structure; a solver-option variant of the structure reads no file)."""
    k = program.key()[:STRUCTURE_KEY]
    layout = _LAYOUTS.get(k)
    if layout is None:
        layout = _read_layout(lib_key)
        if layout is not None:
            _LAYOUTS.put(k, layout)
            # a structure declared here is not new
            MADE["loaded"] += _program_key(program) not in _PROGRAMS
    return layout


def _layout_arrays(layout: _Layout) -> dict[str, np.ndarray]:
    """The layout as arrays (saved beside a library)."""
    index = {
        name: {block: [s.start, s.stop] for block, s in getattr(layout, name).items()}
        for name in ("x_index", "p_index", "g_index")
    }
    return {
        "index": np.array(json.dumps({**index, "cost_names": layout.cost_names})),
        **{name: getattr(layout, name) for name in ("lbx", "ubx", "lbg", "ubg")},
    }


def _read_layout(lib_key: str) -> _Layout | None:
    """The layout saved beside the library of ``lib_key`` (None: absent or unreadable)."""
    data = codegen.read_layout(lib_key)
    try:
        meta = json.loads(str(data["index"])) if data is not None else None
        if meta is None:
            return None
        index = {
            name: {block: slice(*ends) for block, ends in meta[name].items()}
            for name in ("x_index", "p_index", "g_index")
        }
        bounds = {n: np.asarray(data[n], dtype=float) for n in ("lbx", "ubx", "lbg", "ubg")}
        return _Layout(**index, cost_names=list(meta["cost_names"]), **bounds)
    except (KeyError, ValueError, TypeError):
        return None


def symbolic(program: Compilable) -> _Program:
    """The symbolic program of this structure (declared once, then cached; again when its
    collision kernels were being compiled and some builder has finished since)."""
    key = _program_key(program)
    found = _PROGRAMS.get(key)
    if found is None or _stale(found.kernels_epoch):
        found = _PROGRAMS.put(key, _declare(program))
    return found


def _stale(kernels_epoch: int | None) -> bool:
    """Whether something declared at ``kernels_epoch`` could now have compiled kernels."""
    return kernels_epoch is not None and kernels_epoch != native.epoch()


def _program_key(program: Compilable) -> tuple[Any, ...]:
    """What a symbolic program is cached under: its structure, and whether its collision
    kernels run in machine code (the same arithmetic, :mod:`posturegen.collision.native`)."""
    return (*program.key()[:STRUCTURE_KEY], native_kernels(program))


def native_kernels(program: Compilable) -> bool:
    """Whether the program's collision kernels are compiled: when the program runs on the
    virtual machine while a C compiler is at hand (codegen modes ``cached``, ``background``).
    In ``auto`` and ``sync`` its library is built before its first solve; in ``off`` nothing
    is compiled."""
    return program.solver_options.codegen_mode() in ("cached", "background")


# the program of the terms declared first (Term.late: the others come after), per robot and
# their keys: a problem whose collision rows grow declares only them again
_EARLY: BoundedCache[BuildContext] = BoundedCache("programs without the late terms", CACHE_SIZE)


def _declare(program: Compilable) -> _Program:
    """Every term declares its pieces; the program's vectors, functions and layout."""
    MADE["declared"] += 1
    epoch = native.epoch()  # before the kernels are looked for
    terms = list(enumerate(program.terms()))

    def declare(ctx: BuildContext, which: list[tuple[int, Term]]) -> BuildContext:
        for position, term in which:
            ctx.nlp.declaring = position
            term.declare(ctx)
        return ctx

    def make() -> BuildContext:
        ctx = BuildContext(robot=program.robot, nlp=NLP(), kin=program.robot.kinematics)
        return declare(ctx, [(i, t) for i, t in terms if not t.late])

    key = (program.key()[0], tuple((i, t.key()) for i, t in terms if not t.late))
    ctx = _EARLY.get_or_make(key, make).extended()
    ctx.native_kernels = native_kernels(program)
    ctx = declare(ctx, [(i, t) for i, t in terms if t.late])
    nlp = ctx.nlp.ordered()  # the late terms' blocks where their terms stand
    if program.elastic is not None:
        soften(nlp, program.elastic)
    x = ca.vertcat(*[v[0] for v in nlp.x.values()])
    p = ca.vertcat(*nlp.p.values()) if nlp.p else ca.SX(0, 1)
    g = ca.vertcat(*[v[0] for v in nlp.g.values()])
    cost = sum(nlp.costs.values()) if nlp.costs else ca.SX(0)
    names = list(nlp.outputs)
    return _Program(
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
        kernels_epoch=epoch if ctx.kernels_pending else None,
    )


def numeric(
    program: Compilable, compiled: _Layout
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x0, p, lbg, ubg) of this instance for a compiled structure."""
    x0 = initial_guess(program, compiled)
    p = np.zeros(sum(s.stop - s.start for s in compiled.p_index.values()))
    lbg, ubg = compiled.lbg.copy(), compiled.ubg.copy()
    for term in program.terms():
        for name, value in term.parameters(program).items():
            p[compiled.p_index[name]] = np.ravel(value, order="F")
        for name, (lb, ub) in term.bounds(program).items():
            lbg[compiled.g_index[name]] = lb
            ubg[compiled.g_index[name]] = ub
    return x0, p, lbg, ubg


def initial_guess(program: Compilable, compiled: _Layout) -> np.ndarray:
    """x0 (n_x,) of this instance for a compiled structure: every term's initial guess."""
    x0 = np.zeros(compiled.n_x)
    for term in program.terms():
        for name, value in term.initial_guess(program).items():
            x0[compiled.x_index[name]] = np.ravel(value, order="F")
    return x0


def summary(program: Compilable) -> str:
    """Human-readable sizes of the program: variable and constraint blocks, cost terms."""
    c = symbolic(program)
    model = program.robot.model
    lines = [
        f"robot {program.robot.name}: nq={model.nq}, nv={model.nv}",
        f"variables: {c.n_x}",
    ]
    lines += [f"  {n}: {s.stop - s.start}" for n, s in c.x_index.items()]
    lines.append(f"constraints: {c.n_g}")
    lines += [f"  {n}: {s.stop - s.start}" for n, s in c.g_index.items()]
    lines.append("costs: " + ", ".join(c.cost_names))
    return "\n".join(lines)


def constraint_counts(program: Compilable) -> dict[str, int]:
    """Rows per constraint block."""
    c = symbolic(program)
    return {n: s.stop - s.start for n, s in c.g_index.items()}


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
        check_derivatives(name, d, sl.stop - sl.start)
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


def _columns(z: ca.SX, x: ca.SX) -> list[int]:
    """Where each symbol of z sits in x (∂z/∂x is a selection matrix)."""
    if not all(z[k].is_symbolic() for k in range(z.shape[0])):
        raise SolveError("a block's derivatives must be taken w.r.t. variables of the program")
    rows, cols = ca.jacobian(z, x).sparsity().get_triplet()
    if sorted(rows) != list(range(z.shape[0])):
        raise SolveError("a block's derivatives are taken w.r.t. symbols that are not variables")
    return [c for _, c in sorted(zip(rows, cols, strict=True))]
