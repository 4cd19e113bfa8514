"""Shared fixtures: robots (Talos bundled; HRP-2 and ATLAS from ../shared/robots)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pinocchio as pin
import pytest

from posturegen.robot import load_bundled

# Solvers run CasADi's virtual machine in the tests (no background compilation of every reused
# structure into ~/.cache); tests/test_codegen.py sets its modes explicitly.
os.environ.setdefault("POSTUREGEN_CODEGEN", "off")

ROOT = Path(__file__).resolve().parents[1]
SHARED_ROBOTS = ROOT.parent / "shared" / "robots"
HRP2_URDF = SHARED_ROBOTS / "hrp2" / "hrp2.urdf"
ATLAS_URDF = SHARED_ROBOTS / "drake_models" / "atlas" / "atlas_convex_hull.urdf"


@pytest.fixture(scope="session")
def talos():
    return load_bundled("talos")


def shared_model(urdf: Path) -> pin.Model:
    """A free-flyer model of one of the shared URDFs; fails loudly when shared/ is missing."""
    if not urdf.is_file():
        raise FileNotFoundError(
            f"{urdf} missing: tests read the paper's robots from ../shared/robots"
        )
    return pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())


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
