"""The SQP's loop in C: :func:`posturegen.solver.sqp.core.sqp`'s iterations, the same steps
in the same order, without the interpreter between them.

A posture SQP spends half its time in Python and numpy between the C it calls (a Talos
near-body reach: 33 % of the samples in the interpreter, 19 % in numpy, 16 % in the generated
functions, 14 % in daqp). ``kernel.c`` (next to this file) runs the loop: it evaluates the
program's functions through their CasADi buffers (the oracle's, in place: generated C when the
structure's library is built, the virtual machine otherwise), forms the model (S H S + δ I, its
positive definiteness decided by the same LAPACK Cholesky as :mod:`.hessian`; the damped BFGS
update), the QP's bounds, the step's promise, the penalty, the ratio test, the region and the
stopping tests. It asks Python (a callback) for what is not arithmetic on its arrays: each QP
(the QP backends of :mod:`posturegen.solver.qp`, with the relaxation and the elastic QP of
:mod:`.core`), and the convexification when neither S H S + δ I nor the rows held make it
positive definite (:func:`.hessian.convexified`'s eigenvalue ways). core.py stays the
reference and the path without a C compiler; ``tests/test_sqp_native.py`` holds them to the
same runs.

Sums are the C loop's, not numpy's (pairwise, BLAS): the iterates differ from core's in the last
bits, and a borderline decision can differ. The library is compiled once per machine into
``$POSTUREGEN_CACHE/kernels`` (:func:`posturegen._compiler.kernel_library`).
``$POSTUREGEN_NO_NATIVE_SQP`` set: core's loop."""

from __future__ import annotations

import ctypes
import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..._cache import BoundedCache, Ref
from ..._compiler import capsule_pointer, kernel_library
from ..buffered import eval_address
from ..compile import CACHE_SIZE
from ..qp import registry
from ..qp.base import QP, QPSolution
from . import core
from .hessian import AUGMENT, CURVATURE_MAX, DELTA, by_eigenvalues
from .iterate import Bounds
from .oracle import Oracle

# kernel.c's run statuses, by code; None: a callback raised (re-raised here)
STATUSES = (
    core.UNFINISHED,
    core.SUCCEEDED,
    core.ACCEPTABLE,
    "Infeasible_Problem_Detected",
    "Maximum_CpuTime_Exceeded",
    "Error_In_Step_Computation",
    "Search_Direction_Becomes_Too_Small",
    None,
)
_ASK_STEP, _ASK_SOC, _ASK_MODEL = 0, 1, 2

_D = ctypes.POINTER(ctypes.c_double)
_L = ctypes.POINTER(ctypes.c_long)
_U = ctypes.POINTER(ctypes.c_ubyte)
_V = ctypes.c_void_p
_ASK = ctypes.CFUNCTYPE(ctypes.c_long, ctypes.c_long)


def _fields(kind: Any, names: str) -> list[tuple[str, Any]]:
    return [(name, kind) for name in names.split()]


class _Sqp(ctypes.Structure):
    """kernel.c's ``Sqp``, field for field."""

    _fields_ = [
        *_fields(ctypes.c_long, "n m"),
        *_fields(_V, "eval fb_grad fb_jac fb_hess"),
        *_fields(_D, "in_x in_sigma in_lam out_f out_grad out_g out_jac out_hess"),
        *_fields(ctypes.c_long, "nnz_grad nnz_g nnz_jac nnz_hess n_off"),
        *_fields(_L, "at_grad at_g at_jac at_upper at_mirrored off"),
        *_fields(_D, "lbx ubx lbg ubg scale"),
        ("equal", _U),
        *_fields(ctypes.c_long, "max_iter stall_iterations hessian_every flat_iterations"),
        *_fields(ctypes.c_double, "max_time_s tol_primal tol_dual radius0 radius_min penalty0"),
        *_fields(
            ctypes.c_double,
            "eta shrink radius_max penalty_max delta curvature_max linear_tol flat_change",
        ),
        ("penalty_over", ctypes.c_double),
        ("augment", _D),
        ("n_augment", ctypes.c_long),
        ("ask", _ASK),
        ("potrf", _V),
        *_fields(_D, "X GRAD G JAC VIOL F L1 WORST lam_g lam_x H B c A Cm"),
        *_fields(_U, "rows held_x"),
        *_fields(ctypes.c_long, "k_C modified model_version"),
        *_fields(_D, "lb ub lbA ubA duals"),
        ("has_duals", ctypes.c_long),
        *_fields(_D, "soc_lbA soc_ubA soc_duals qd qlb qlr"),
        *_fields(ctypes.c_long, "q_solved q_iters q_elastic"),
        ("penalty", ctypes.c_double),
        *_fields(_D, "d lam_b lam_r"),
        *_fields(
            ctypes.c_long,
            "iterations qp_iterations modified_hessians status cur history_len",
        ),
        ("wall_s", ctypes.c_double),
        ("rows_bound", _U),
        ("history", _D),
        *_fields(_D, "w1 w2 w3 w4 wm wnn wnn2 gram costs"),
    ]


@functools.cache
def _library() -> ctypes.CDLL | None:
    """kernel.c compiled (at its first use on this machine), or None: no C compiler, a C
    ``long`` that is not 64 bits, CasADi's evaluation not found, or the build failed."""
    if ctypes.sizeof(ctypes.c_long) != 8 or os.environ.get("POSTUREGEN_NO_NATIVE_SQP"):
        return None
    if eval_address() is None or _potrf_address() is None:
        return None
    try:
        source = (Path(__file__).parent / "kernel.c").read_text()
    except OSError:  # an install without the package's C sources
        return None
    lib = kernel_library("sqp", source)
    if lib is None:
        return None
    lib.sqp_run.restype = ctypes.c_long
    lib.sqp_run.argtypes = [ctypes.POINTER(_Sqp)]
    lib.sqp_size.restype = ctypes.c_long
    if lib.sqp_size() != ctypes.sizeof(_Sqp):  # a record of another version of kernel.c
        return None
    return lib


@functools.cache
def _potrf_address() -> int | None:
    """LAPACK's dpotrf as SciPy exports it to C (the Cholesky factorization of
    :func:`.hessian._factorizes`)."""
    try:
        from scipy.linalg import cython_lapack

        capsule = cython_lapack.__pyx_capi__["dpotrf"]
    except (ImportError, AttributeError, KeyError):
        return None
    return capsule_pointer(capsule)


def available() -> bool:
    """Whether the C loop runs here (else core's)."""
    return _library() is not None


def _pointer(a: np.ndarray, kind: Any) -> Any:
    return a.ctypes.data_as(kind)


class Kernel:
    """kernel.c's arrays for one oracle (n variables, m rows), reused by its runs (one at a
    time: the oracle's structure's lock)."""

    def __init__(self, oracle: Oracle) -> None:
        n, m = oracle.n, oracle.m
        parts = oracle.parts()
        self.n, self.m = n, m
        self._parts = parts  # its buffers are evaluated from C: kept alive with the kernel
        self.a: dict[str, np.ndarray] = {}
        zeros = {
            "X": (2, n), "GRAD": (2, n), "G": (2, m), "JAC": (2, m, n), "VIOL": (2, m),
            "F": (2,), "L1": (2,), "WORST": (2,), "lam_g": (m,), "lam_x": (n,),
            "H": (n, n), "B": (n, n), "c": (n,), "A": (m, n), "Cm": (m + n, n),
            "lb": (n,), "ub": (n,), "lbA": (m,), "ubA": (m,), "duals": (n + m,),
            "soc_lbA": (m,), "soc_ubA": (m,), "soc_duals": (n + m,),
            "qd": (n,), "qlb": (n,), "qlr": (m,), "d": (n,), "lam_b": (n,), "lam_r": (m,),
            "w1": (n,), "w2": (n,), "w3": (n,), "w4": (n,), "wm": (m + n,), "wnn": (n, n),
            "wnn2": (n, n), "gram": (n, n), "augment": (len(AUGMENT),),
            "costs": (core.FLAT_ITERATIONS,),
            "lbx": (n,), "ubx": (n,), "lbg": (m,), "ubg": (m,), "scale": (n,),
        }  # fmt: skip
        for name, shape in zeros.items():
            self.a[name] = np.zeros(shape)
        for name, size in (("equal", m), ("rows", m), ("held_x", n), ("rows_bound", m)):
            self.a[name] = np.zeros(size, dtype=np.uint8)
        self._history = np.zeros(0)
        s = self.s = _Sqp()
        s.n, s.m = n, m
        s.eval, s.potrf = eval_address(), _potrf_address()
        s.fb_grad, s.fb_jac, s.fb_hess = (b.address() for b in (parts.grad, parts.jac, parts.hess))
        s.in_x, s.in_sigma, s.in_lam = (_pointer(a, _D) for a in (parts.x, parts.sigma, parts.lam))
        s.out_f, s.out_grad = (_pointer(o, _D) for o in parts.grad.outputs)
        s.out_g, s.out_jac = (_pointer(o, _D) for o in parts.jac.outputs)
        s.out_hess = _pointer(parts.hess.outputs[0], _D)
        self._at = [
            np.ascontiguousarray(a, dtype=np.int64)
            for a in (
                parts.at_grad, parts.at_g, parts.at_jac, parts.at_upper, parts.at_mirrored,
                parts.off,
            )
        ]  # fmt: skip
        s.at_grad, s.at_g, s.at_jac, s.at_upper, s.at_mirrored, s.off = (
            _pointer(a, _L) for a in self._at
        )
        s.nnz_grad, s.nnz_g, s.nnz_jac = (a.size for a in self._at[:3])
        s.nnz_hess, s.n_off = parts.hess.outputs[0].size, self._at[5].size
        for name, a in self.a.items():
            setattr(s, name, _pointer(a, _U if a.dtype == np.uint8 else _D))
        self._ask = _ASK(self._answer)  # kept: C holds its address
        s.ask = self._ask
        self._run: _Run | None = None

    def run(
        self,
        x0: np.ndarray,
        bounds: Bounds,
        options: core.SQPOptions,
        lam_g0: np.ndarray | None,
        lam_x0: np.ndarray | None,
        duals0: np.ndarray | None,
    ) -> core.SQPRun:
        """core.sqp's run, by kernel.c (see :func:`sqp`)."""
        a, s = self.a, self.s
        for name in ("lbx", "ubx", "lbg", "ubg", "scale"):
            a[name][:] = getattr(bounds, name)
        a["equal"][:] = bounds.equal
        np.clip(x0, bounds.lbx, bounds.ubx, out=a["X"][0])
        a["lam_g"][:] = 0.0 if lam_g0 is None else lam_g0
        a["lam_x"][:] = 0.0 if lam_x0 is None else lam_x0
        s.has_duals = duals0 is not None
        if duals0 is not None:
            a["duals"][:] = duals0
        a["rows_bound"][:] = 0
        if self._history.size < 3 * options.max_iter:
            self._history = np.zeros(3 * options.max_iter)
        s.history = _pointer(self._history, _D)
        self._settings(options)
        record = core.SQPRun(a["X"][0], 0.0, a["lam_g"], a["lam_x"], core.UNFINISHED, 0, 0,
                             None, 0.0)  # fmt: skip
        record.rows_bound = a["rows_bound"].view(bool)
        self._run = _Run(self, bounds, options, record)
        try:
            code = _library().sqp_run(ctypes.byref(s))  # type: ignore[union-attr]
            error = self._run.error
        finally:
            self._run = None
        if error is not None:
            raise error
        return self._result(record, STATUSES[code])

    def _settings(self, options: core.SQPOptions) -> None:
        """The run's options and core's constants into the kernel's record."""
        s = self.s
        s.max_iter, s.max_time_s = options.max_iter, options.max_time_s
        s.tol_primal, s.tol_dual = options.tol_primal, options.tol_dual
        s.radius0, s.radius_min, s.penalty0 = options.radius, options.radius_min, options.penalty
        s.stall_iterations, s.hessian_every = core.STALL_ITERATIONS, core.HESSIAN_EVERY
        s.flat_iterations, s.flat_change = core.FLAT_ITERATIONS, core.FLAT_CHANGE
        s.eta, s.shrink, s.radius_max = core.ETA, core.SHRINK, core.RADIUS_MAX
        s.penalty_max, s.linear_tol = core.PENALTY_MAX, core.LINEAR_TOL
        s.penalty_over = core.PENALTY_OVER_MULTIPLIERS
        s.delta, s.curvature_max = DELTA, CURVATURE_MAX
        self.a["augment"][:] = AUGMENT
        s.n_augment = len(AUGMENT)
        s.iterations = s.qp_iterations = s.modified_hessians = s.history_len = 0
        s.cur, s.k_C, s.modified = 0, 0, 0

    def _result(self, record: core.SQPRun, status: str | None) -> core.SQPRun:
        """The run's record from the kernel's (copies: the arrays are the kernel's)."""
        a, s = self.a, self.s
        record.x, record.f = a["X"][s.cur].copy(), float(a["F"][s.cur])
        record.lam_g, record.lam_x = a["lam_g"].copy(), a["lam_x"].copy()
        record.status = str(status)
        record.iterations, record.qp_iterations = s.iterations, s.qp_iterations
        record.duals = a["duals"].copy() if s.has_duals else None
        record.wall_s, record.modified_hessians = s.wall_s, s.modified_hessians
        history = self._history[: 3 * s.history_len].reshape(-1, 3)
        record.history = [(float(f), float(v), float(r)) for f, v, r in history]
        record.rows_bound = a["rows_bound"].astype(bool)
        return record

    def _answer(self, kind: int) -> int:
        """kernel.c's question ``kind`` answered into its arrays; 1 when it raised (kept for
        :meth:`run` to raise)."""
        run = self._run
        if run is None:
            return 1
        try:
            run.answer(kind)
            return 0
        except BaseException as exc:  # noqa: BLE001 (re-raised after the C loop returns)
            run.error = exc
            return 1


class _Run:
    """What a run's questions need: the bounds, the options, core's record of the QPs
    (relaxed, elastic, the rows that bound the run), and the model's arrays as the QPs hold
    them (new array objects at each new model: a QP backend keeps its factorization for the
    QPs that hold the same B, c and A)."""

    def __init__(
        self, kernel: Kernel, bounds: Bounds, options: core.SQPOptions, record: core.SQPRun
    ) -> None:
        self.kernel, self.bounds, self.options, self.record = kernel, bounds, options, record
        self.error: BaseException | None = None
        self.version = -1
        self.model: tuple[np.ndarray, np.ndarray, np.ndarray] = (np.zeros(0),) * 3

    def answer(self, kind: int) -> None:
        a, s = self.kernel.a, self.kernel.s
        if kind == _ASK_MODEL:
            self._convexified()
            return
        if s.model_version != self.version:
            self.version = s.model_version
            self.model = (a["B"].view(), a["c"].view(), a["A"].view())
        B, c, A = self.model
        if kind == _ASK_STEP:
            duals = a["duals"] if s.has_duals else None
            qp = QP(B, c, A, a["lb"], a["ub"], a["lbA"], a["ubA"], self.bounds.equal, duals)
            sol = core._relaxed(qp, self.options, self.record)
            s.q_elastic = not sol.solved
            if not sol.solved:
                sol, s.penalty = core._elastic(qp, s.penalty, self.options, self.record)
        else:  # the second-order correction
            qp = QP(B, c, A, a["lb"], a["ub"], a["soc_lbA"], a["soc_ubA"], self.bounds.equal,
                    a["soc_duals"])  # fmt: skip
            sol = registry.solve(qp, self.options.qp)
        self._write(sol)

    def _write(self, sol: QPSolution) -> None:
        a, s = self.kernel.a, self.kernel.s
        a["qd"][:], a["qlb"][:], a["qlr"][:] = sol.d, sol.lam_bounds, sol.lam_rows
        s.q_solved, s.q_iters = sol.solved, sol.iterations

    def _convexified(self) -> None:
        """hessian.by_eigenvalues of the kernel's ∇²L, with the rows and bounds it holds: the
        kernel found neither S H S + δ I (its B̃ now) nor the τ ladder positive definite."""
        a, s, n = self.kernel.a, self.kernel.s, self.kernel.n
        held = np.vstack([a["A"][a["rows"].view(bool)], np.eye(n)[a["held_x"].view(bool)]])
        Hs = a["H"] * np.outer(self.bounds.scale, self.bounds.scale)
        B, modified, C = by_eigenvalues(Hs, a["B"].copy(), held)
        a["B"][:] = B
        s.modified = int(modified)
        s.k_C = C.shape[0] if C.any() else 0
        a["Cm"][: s.k_C] = C[: s.k_C]


# a kernel per oracle (the oracles' own cache holds one per structure)
_KERNELS: BoundedCache[Kernel] = BoundedCache("SQP kernels", CACHE_SIZE)


def sqp(
    oracle: Oracle,
    x0: np.ndarray,
    bounds: Bounds,
    options: core.SQPOptions,
    lam_g0: np.ndarray | None = None,
    lam_x0: np.ndarray | None = None,
    duals0: np.ndarray | None = None,
) -> core.SQPRun:
    """:func:`.core.sqp` by the C loop when it is available here, else core's (and for an
    oracle that is not an :class:`.Oracle`: one of a test's, whose functions C cannot call)."""
    if not available() or not isinstance(oracle, Oracle):
        return core.sqp(oracle, x0, bounds, options, lam_g0, lam_x0, duals0)
    kernel = _KERNELS.get_or_make(Ref(oracle), lambda: Kernel(oracle))
    return kernel.run(x0, bounds, options, lam_g0, lam_x0, duals0)
