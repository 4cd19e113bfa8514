"""What a solve returns: the frozen :class:`Result` (a posture, its forces and torques, its
re-check, its counts and timings) and the counts of a call's runs added into it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io.posture_file import write_posture
from ..verify import VerifyReport
from .runs import Run


@dataclass(frozen=True)
class ContactForce:
    """A force on the robot [N] at a world point [m], applied to a point of ``frame``."""

    frame: str
    point: np.ndarray  # (3,) world [m]
    force: np.ndarray  # (3,) world [N]


@dataclass(frozen=True)
class Result:
    """A solved posture. ``success`` means the solver converged and the re-check passed."""

    success: bool
    status: str  # the solver's return status (IPOPT's names, the SQP's too)
    message: str  # why it failed, or "verified"
    iterations: int  # of every run of the call, SQP and IPOPT
    solve_time_s: float  # the solvers' own wall time [s]
    build_time_s: float  # time to build the solver (0 when it came from the cache) [s]
    q: np.ndarray  # (nq,) Pinocchio order: base xyz, quaternion xyzw, joints
    torques: np.ndarray  # (nj,) actuated joints, velocity order [N·m]
    forces: dict[str, tuple[ContactForce, ...]]  # per contact name
    cost: float
    verification: VerifyReport
    posture: dict[str, Any]  # the posture-file content
    # why no posture was found, one line (posturegen.solver.diagnose.diagnose); "" when not
    # diagnosed
    diagnosis: str = ""
    # the last IPOPT run's program: its constraint rows (its collision rows included) and
    # whether it ran generated C (posturegen.solver.codegen)
    constraint_rows: int = 0
    generated_c: bool = False
    # the last run's variables (n_x,) and their blocks: what starts another solve
    # (solve(problem, start=result))
    x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    x_blocks: dict[str, slice] = dataclasses.field(default_factory=dict)
    # and its multipliers: of the variables' bounds (n_x,), of each constraint block
    lam_x: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    lam_g: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    # the solver of the last run ("sqp" or "ipopt", SolverOptions.method) and the iterations
    # of each solver over the call's runs
    method: str = "ipopt"
    iterations_by_method: dict[str, int] = dataclasses.field(default_factory=dict)
    verify_time_s: float = 0.0  # the re-check of the returned posture [s]
    wall_time_s: float = 0.0  # the whole call: builds, runs, active-set rounds, re-checks [s]

    @property
    def max_violation(self) -> float:
        """The worst re-check relative to its tolerance (<= 1: all passed; see
        :attr:`VerifyReport.max_violation`)."""
        return self.verification.max_violation

    def write(self, path: str | Path) -> Path:
        """Write the posture file (JSON)."""
        return write_posture(path, self.posture)


def after_failed(failed: Result, alone: Result) -> Result:
    """The answer of an ``auto`` call whose SQP call ``failed``: IPOPT's call (``alone``),
    counted with every run of both."""
    by_method = dict(failed.iterations_by_method)
    for method, n in alone.iterations_by_method.items():
        by_method[method] = by_method.get(method, 0) + n
    return tallied(
        alone,
        failed.iterations + alone.iterations,
        failed.solve_time_s + alone.solve_time_s,
        failed.posture.get("ipopt_runs", 0) + alone.posture.get("ipopt_runs", 0),
        failed.build_time_s + alone.build_time_s,
        by_method,
        verify_time_s=failed.verify_time_s + alone.verify_time_s,
    )


def counted(result: Result, runs: list[Run]) -> Result:
    """``result`` with the iterations and times of every run of the call (those of the
    continuations that did not succeed too), in its posture's fields as well."""
    return tallied(
        result,
        sum(r.iterations for r in runs),
        sum(r.solve_time_s for r in runs),
        len(runs),
        sum(r.build_time_s for r in runs),
        by_method_of(runs),
    )


def tallied(
    result: Result,
    iterations: int,
    solve_time_s: float,
    runs: int,
    build_time_s: float,
    by_method: dict[str, int],
    **more: Any,
) -> Result:
    """``result`` counting ``iterations``, ``solve_time_s`` [s] and ``runs`` (in its
    posture's fields as well), ``build_time_s`` [s], ``by_method`` and ``more`` fields."""
    result.posture.update(
        {"iterations": iterations, "solve_time_s": solve_time_s, "ipopt_runs": runs}
    )
    return dataclasses.replace(
        result,
        iterations=iterations,
        solve_time_s=solve_time_s,
        build_time_s=build_time_s,
        iterations_by_method=by_method,
        **more,
    )


def by_method_of(runs: list[Run]) -> dict[str, int]:
    """Iterations of the runs per solver method."""
    return {m: sum(r.iterations for r in runs if r.method == m) for m in {r.method for r in runs}}
