"""The QP backends of the SQP, by name, in the order they are tried: daqp, then proxsuite.
A backend is one file (``*_backend.py``) with a class that has ``name``, ``available()`` and
``solve(QP) -> QPSolution``; :func:`register` adds a user's own."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...errors import InputError, SolveError
from .base import QP, QPBackend, QPSolution
from .daqp_backend import DaqpBackend
from .proxsuite_backend import ProxsuiteBackend

_BACKENDS: dict[str, QPBackend] = {}


def register(backend: QPBackend) -> QPBackend:
    """Add ``backend`` (its ``name`` replaces a backend of that name) and return it."""
    _BACKENDS[backend.name] = backend
    return backend


register(DaqpBackend())
register(ProxsuiteBackend())


def names() -> list[str]:
    """The registered backends' names, in the order they are tried."""
    return list(_BACKENDS)


def available() -> list[str]:
    """The registered backends that can run here."""
    return [name for name, backend in _BACKENDS.items() if backend.available()]


def backend(name: str | None = None) -> QPBackend:
    """The backend ``name``, or the first available one."""
    if name is None:
        ready = available()
        if not ready:
            raise SolveError("no QP solver: pip install daqp (or proxsuite)")
        return _BACKENDS[ready[0]]
    if name not in _BACKENDS:
        raise InputError(
            "solver.qp", f"unknown QP solver {name!r}", f"use one of: {', '.join(names())}"
        )
    return _BACKENDS[name]


def solve(qp: QP, name: str | None = None) -> QPSolution:
    """Solve ``qp`` with backend ``name`` (default: the first available); when it fails (not
    when it proves the QP infeasible) the next available backend tries."""
    first = backend(name)
    solution = _checked(first.solve(qp))
    if solution.status != "failed":
        return solution
    for other in available():
        if other != first.name:
            solution = _checked(_BACKENDS[other].solve(qp))
            if solution.status != "failed":
                return solution
    return solution


def _checked(solution: QPSolution) -> QPSolution:
    """The solution, "failed" when a solved one holds a value that is not finite."""
    if not solution.solved:
        return solution
    finite = (
        np.isfinite(solution.d).all()
        and np.isfinite(solution.lam_bounds).all()
        and np.isfinite(solution.lam_rows).all()
    )
    if not finite:
        return dataclasses.replace(solution, status="failed")
    return solution
