"""Choosing a backend by name: ``local`` (posturegen.batch.local) or ``ray``
(posturegen.batch.ray_backend)."""

from __future__ import annotations

from collections.abc import Sequence

from ..errors import InputError
from .jobs import Job
from .local import LocalBackend
from .ray_backend import RayBackend

BACKENDS = ("local", "ray")


def open_backend(
    backend: str = "local",
    workers: int | None = None,
    address: str | None = None,
    diagnose: bool = False,
    warm: Sequence[Job] = (),
) -> LocalBackend | RayBackend:
    """The backend's workers, started (``warm`` jobs solved by each worker first);
    ``diagnose``: failures are diagnosed in the workers (posturegen.solver.diagnose)."""
    if workers is not None and workers < 1:
        raise InputError("workers", f"{workers} workers", "give an integer >= 1")
    if backend == "local":
        if address is not None:
            raise InputError("address", "an address is for the ray backend", "add backend ray")
        return LocalBackend(workers, diagnose, warm)
    if backend == "ray":
        return RayBackend(workers, diagnose, warm, address)
    raise InputError("backend", f"unknown backend '{backend}'", f"use {' or '.join(BACKENDS)}")
