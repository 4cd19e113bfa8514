"""``joints``: some joints at given values, or within ranges."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..nlp import ArrayLike
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


@register_task
@dataclass
class JointsTask(Task):
    """q_j = value (or lo <= q_j <= hi) [rad] or [m] for each joint j named in ``values``;
    soft: weight · Σ excess_j² / (0.1 rad)²."""

    kind: ClassVar[str] = "joints"
    unit: ClassVar[str] = "rad"
    fields: ClassVar[dict[str, Field]] = {
        "values": Field("joint_values", "[rad] or [m] by joint name: a value or [min, max]"),
    }

    values: dict[str, float | np.ndarray]

    def subject(self) -> str:
        return "joints"

    def errors(self, f: Frames) -> dict[str, Expr]:
        return {"joints": f.vertcat(*(f.joint(name) for name in self.values))}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        bounds = [np.broadcast_to(np.asarray(v, dtype=float), (2,)) for v in self.values.values()]
        return {"joints": (np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds]))}

    def blocked(self, block: str, amount: float) -> str:
        names = ", ".join(self.values)
        return f"joint values of task {self.index} ({names}) are {amount:.3g} rad beyond reach"
