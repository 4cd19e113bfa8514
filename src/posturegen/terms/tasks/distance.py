"""``distance``: the distance between two frames' origins, a value or a range."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...errors import InputError
from ..nlp import ArrayLike
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


@register_task
@dataclass
class DistanceTask(Task):
    """d = ‖p_world_frame - p_world_other‖ [m] (smoothed at 0 by 1e-12 m²): d = distance, or
    range[0] <= d <= range[1]."""

    kind: ClassVar[str] = "distance"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "one of the robot's frames"),
        "other": Field("frame", "the other frame"),
        "distance": Field("number", "[m] the distance wanted", default=None, minimum=0.0),
        "range": Field("range", "[m] [min, max] of the distance", default=None),
    }

    frame: str
    other: str
    distance: float | None = None
    range: np.ndarray | None = None  # (2,) [m]

    def subject(self) -> str:
        return f"{self.frame}-{self.other}"

    def check(self, fld: str) -> None:
        if (self.distance is None) == (self.range is None):
            raise InputError(
                fld,
                "needs distance or range (one of them)",
                "add distance: 0.3 or range: [0.2, 0.4]",
            )

    def errors(self, f: Frames) -> dict[str, Expr]:
        return {"distance": f.norm(f.position(self.frame) - f.position(self.other))}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        lo, hi = (self.distance, self.distance) if self.range is None else self.range
        return {"distance": (float(lo), float(hi))}
