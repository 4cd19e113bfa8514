"""Friction at a contact point: the exact cone |f_t| <= μ f_n or an inscribed pyramid."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .. import _fields as F
from ..errors import InputError

FRICTION_KINDS = ("pyramid", "cone")


@dataclass(frozen=True)
class FrictionModel:
    """Friction cone |f_t| <= μ f_n, exactly (``cone``) or as an inscribed pyramid with
    ``faces`` faces: (cos θ_k, sin θ_k)·f_t <= μ cos(π/faces) f_n."""

    kind: str = "pyramid"  # "pyramid" | "cone"
    faces: int = 4

    def __post_init__(self) -> None:
        if self.kind not in FRICTION_KINDS:
            raise InputError(
                "friction.model",
                f"unknown friction model {self.kind!r}",
                f"use one of: {', '.join(FRICTION_KINDS)}",
            )
        F.integer(self.faces, "friction.faces", 3, "use 4 or 8")

    def constraints(self, phi: ca.SX, mu: ca.SX) -> ca.SX:
        """Rows that must be <= 0 for local force φ = (f_t, f_n) (3,)."""
        if self.kind == "cone":
            return ca.vertcat(phi[0] ** 2 + phi[1] ** 2 - mu**2 * phi[2] ** 2)
        rows = []
        for k in range(self.faces):
            th = 2 * np.pi * k / self.faces
            rows.append(
                np.cos(th) * phi[0] + np.sin(th) * phi[1] - mu * np.cos(np.pi / self.faces) * phi[2]
            )
        return ca.vertcat(*rows)
