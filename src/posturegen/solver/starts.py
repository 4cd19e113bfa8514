"""Starting a solve from a solved posture: a planner's next query is usually close to one it
already asked, and IPOPT started there needs fewer iterations than from the initial posture.

:func:`start_vector` lays out a solved posture's variables for another problem of the same
robot: the blocks that exist in both with the same size are carried (joints, base position,
forces, torques, ellipses), the base rotation is re-expressed against the new problem's
R0 (w = log3(R0ᵀ·R)), the others keep the new problem's own initial guess. Without
collision rows the start's multipliers warm-start IPOPT too (:func:`posturegen.solver.solve.
solve`).

:class:`NearestStarts` remembers the verified solutions of a loop of problems, per problem
structure, and returns the one whose parameters (task targets, contact poses) are nearest to
a new problem's: ``solve(problem, start=starts.nearest(problem))`` then ``starts.add(problem,
result)``.
"""

from __future__ import annotations

import collections
from collections.abc import Hashable, Mapping
from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from ..terms.configuration import BASE_ROTATION_BOUND
from .problem import Problem, Program

# IPOPT's initial barrier parameter from a start without multipliers (measured on
# talos-reach-balance-free, 40 problems, each started from the nearest of those solved before
# it: 11 median iterations at IPOPT's 0.1, 9 at 1e-3, against 12 from the initial posture).
START_MU_INIT = 1e-3
# With the start's multipliers IPOPT warm-starts (SolverOptions.warm_start) from this barrier
# parameter: on the nearest pass of talos-reach-balance-free (50 problems, seed 0), 5 median
# iterations and 274 in all at 1e-6, against 6 and 346 at 1e-5 (the active-set rounds' own
# warm starts keep 1e-5), 5 and 258 at 1e-7; all 50 verified each time
START_WARM_MU_INIT = 1e-6
STARTS_PER_STRUCTURE = 256  # solutions kept per problem structure (oldest dropped)


class Solved(Protocol):
    """What a start needs of a :class:`posturegen.solver.solve.Result`."""

    success: bool
    q: np.ndarray  # (nq,)
    x: np.ndarray  # (n_x,) the last run's variables
    x_blocks: Mapping[str, slice]  # their blocks
    lam_x: np.ndarray  # (n_x,) their bounds' multipliers (empty: none)
    lam_g: Mapping[str, np.ndarray]  # each constraint block's multipliers


def carried(
    values: np.ndarray, old: Mapping[str, slice], new: Mapping[str, slice], default: np.ndarray
) -> np.ndarray:
    """``values`` laid out by the blocks ``old``, moved to the blocks ``new`` (the blocks of
    another size, or new ones, from ``default``)."""
    out = default.copy()
    for name, sl in new.items():
        src = old.get(name)
        if src is not None and src.stop - src.start == sl.stop - sl.start:
            out[sl] = values[src]
    return out


def start_vector(
    program: Program, x_init: np.ndarray, x_index: Mapping[str, slice], start: Solved
) -> np.ndarray:
    """``start``'s variables laid out as ``x_index`` (n_x,): blocks of equal size carried,
    the base rotation relative to this program's R0, the others from ``x_init``."""
    x = carried(start.x, start.x_blocks, x_index, x_init)
    R0 = pin.Quaternion(program.q_init[3:7]).normalized().matrix()
    R = pin.Quaternion(start.q[3:7]).normalized().matrix()
    w = pin.log3(R0.T @ R)  # (3,) [rad]
    x[x_index["base.rotation"]] = np.clip(w, -BASE_ROTATION_BOUND, BASE_ROTATION_BOUND)
    return x


def features(problem: Problem) -> np.ndarray:
    """The problem's parameters (every term's, in declaration order): what differs between
    problems of one structure (targets, contact poses, the initial base rotation)."""
    program = Program.of(problem)
    values = [np.ravel(v) for t in program.terms() for v in t.parameters(program).values()]
    return np.concatenate(values) if values else np.zeros(0)


class NearestStarts:
    """Verified solutions per problem structure; :meth:`nearest` is the one whose
    :func:`features` are nearest (Euclidean) to a new problem's."""

    def __init__(self, size: int = STARTS_PER_STRUCTURE) -> None:
        if size < 1:
            raise ValueError("NearestStarts: size must be >= 1")
        self.size = size
        self._by_key: dict[Hashable, collections.deque[tuple[np.ndarray, Any]]] = {}

    def add(self, problem: Problem, result: Solved) -> None:
        """Remember ``result`` (only when verified)."""
        if result.success:
            kept = self._by_key.setdefault(problem.key(), collections.deque(maxlen=self.size))
            kept.append((features(problem), result))

    def nearest(self, problem: Problem) -> Any:
        """The remembered solution nearest to ``problem`` (None: none of its structure)."""
        kept = self._by_key.get(problem.key())
        if not kept:
            return None
        f = features(problem)
        same = [i for i, (g, _) in enumerate(kept) if g.shape == f.shape]
        if not same:
            return None
        G = np.stack([kept[i][0] for i in same])  # (k, n) their features
        return kept[same[int(np.argmin(np.linalg.norm(G - f, axis=1)))]][1]

    def __len__(self) -> int:
        return sum(len(v) for v in self._by_key.values())
