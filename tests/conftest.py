"""Shared fixtures: robots (all shipped by name: Talos, G1, Romeo, HRP-2, ATLAS)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import pytest

from posturegen.robot import load_bundled, shipped_models_dir

# Solvers run CasADi's virtual machine in the tests (no background compilation of every reused
# structure into ~/.cache); tests/test_codegen.py sets its modes explicitly.
os.environ.setdefault("POSTUREGEN_CODEGEN", "off")

# the URDF files of the paper's robots that posturegen ships (for tests that load them by path)
HRP2_URDF = shipped_models_dir() / "hrp2" / "hrp2.urdf"


@pytest.fixture(scope="session")
def talos():
    return load_bundled("talos")


def first_run_stops_early(real: Callable, calls: list, record: Callable) -> Callable:
    """A stand-in for one of solve()'s steps ``real(problem, x0, prior)`` whose first call
    stops IPOPT after 3 iterations (a failure); each call appends ``record(problem, x0,
    prior)`` to ``calls``."""

    def step(problem: Any, x0: Any, prior: Any) -> Any:
        calls.append(record(problem, x0, prior))
        if len(calls) == 1:
            options = problem.solver_options
            problem.solver_options = dataclasses.replace(options, max_iter=3)
            try:
                return real(problem, x0, prior)
            finally:
                problem.solver_options = options
        return real(problem, x0, prior)

    return step
