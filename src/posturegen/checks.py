"""The re-check's result: one :class:`Check` per verified quantity, in a :class:`VerifyReport`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Check:
    """One verified quantity: its worst value, the tolerance, and whether it passed."""

    name: str
    value: float
    tolerance: float
    detail: str = ""

    @property
    def ok(self) -> bool:
        """value <= tolerance (NaN fails)."""
        return bool(self.value <= self.tolerance)

    @property
    def ratio(self) -> float:
        """value / tolerance (<= 1: passed), unitless; a check of tolerance 0 gives 0 when
        met and inf when not; NaN gives inf."""
        if not self.value <= self.tolerance:
            if self.tolerance > 0 and np.isfinite(self.value):
                return float(self.value / self.tolerance)
            return float("inf")
        return float(max(self.value, 0.0) / self.tolerance) if self.tolerance > 0 else 0.0


@dataclass(frozen=True)
class VerifyReport:
    """All checks of one posture."""

    checks: tuple[Check, ...]
    notes: tuple[str, ...] = ()  # what the checks left out, and why

    @property
    def ok(self) -> bool:
        """Every check passed."""
        return all(c.ok for c in self.checks)

    @property
    def failures(self) -> tuple[Check, ...]:
        """The checks that failed."""
        return tuple(c for c in self.checks if not c.ok)

    @property
    def max_violation(self) -> float:
        """The worst check relative to its own tolerance: max of :attr:`Check.ratio` (<= 1:
        every check passed); unitless, so that metres, radians and relative forces compare."""
        return max((c.ratio for c in self.checks), default=0.0)

    def summary(self) -> str:
        """One line per check."""
        return "\n".join(
            f"{'ok  ' if c.ok else 'FAIL'} {c.name}: {c.value:.3g} (tolerance {c.tolerance:.1g})"
            + (f" {c.detail}" if c.detail and not c.ok else "")
            for c in self.checks
        ) + "".join(f"\nnote {n}" for n in self.notes)
