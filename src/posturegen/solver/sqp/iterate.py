"""An SQP iterate and what it is measured against: lbx <= x <= ubx and lbg <= g(x) <= ubg
with the variables' scales (:class:`Bounds`), and x with f, ∇f, g, J and the rows' violations
(:class:`Iterate`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


def max_abs(v: np.ndarray) -> float:
    """‖v‖∞ (0 for an empty v)."""
    return float(np.max(np.abs(v), initial=0.0))


@dataclass(frozen=True)
class Bounds:
    """lbx <= x <= ubx, lbg <= g(x) <= ubg, and the variables' scales (n,) for the region."""

    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    scale: np.ndarray

    @functools.cached_property
    def equal(self) -> np.ndarray:
        """(m,) bool: the rows with lbg = ubg (read-only)."""
        equal = self.lbg == self.ubg
        equal.flags.writeable = False
        return equal

    def violation(self, g: np.ndarray) -> np.ndarray:
        """(m,) how far each row is outside its bounds (0 inside)."""
        return np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0)


@dataclass
class Iterate:
    """x with f, ∇f, g, J and the rows' violations."""

    x: np.ndarray
    f: float
    grad: np.ndarray  # (n,)
    g: np.ndarray  # (m,)
    J: np.ndarray  # (m, n)
    viol: np.ndarray  # (m,) how far each row is outside its bounds
    l1: float  # ‖viol‖₁
    worst: float  # ‖viol‖∞

    @classmethod
    def of(
        cls, x: np.ndarray, f: float, grad: np.ndarray, g: np.ndarray, J: np.ndarray, bounds: Bounds
    ) -> Iterate:
        """The iterate at x of f, ∇f, g and J, its violations measured against ``bounds``."""
        viol = bounds.violation(g)
        return cls(x, f, grad, g, J, viol, float(np.sum(viol)), max_abs(viol))
