"""``region``: a frame's origin inside a world box or ball (a target region, not a point)."""

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
class RegionTask(Task):
    """p = p_world_frame [m] in a box, min <= p <= max (3 rows), or in a ball,
    ‖p - center‖ <= radius (1 row, smoothed at the centre by 1e-12 m²)."""

    kind: ClassVar[str] = "region"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame"),
        "min": Field("vector", "[m] the box's lowest corner in world", default=None),
        "max": Field("vector", "[m] the box's highest corner in world", default=None),
        "center": Field("vector", "[m] the ball's centre in world", default=None),
        "radius": Field("number", "[m] the ball's radius", default=None, minimum=0.0),
    }

    frame: str
    min: np.ndarray | None = None
    max: np.ndarray | None = None
    center: np.ndarray | None = None
    radius: float | None = None

    def check(self, fld: str) -> None:
        box = self.min is not None and self.max is not None
        ball = self.center is not None and self.radius is not None
        if box == ball or (box and (self.center is not None or self.radius is not None)):
            raise InputError(
                fld,
                "needs min and max (a box) or center and radius (a ball)",
                "add min: [x, y, z] and max: [x, y, z], or center and radius",
            )
        if box and np.any(np.asarray(self.min) > np.asarray(self.max)):
            raise InputError(f"{fld}.min", "above max on some axis", "write min <= max")

    def target_point(self) -> np.ndarray | None:
        if self.center is not None:
            return np.asarray(self.center, dtype=float)
        return 0.5 * (np.asarray(self.min) + np.asarray(self.max))

    def errors(self, f: Frames) -> dict[str, Expr]:
        p = f.position(self.frame)
        if self.center is None:
            return {"box": p}
        return {"ball": f.norm(p - f.param("center", self.center))}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        if self.center is None:
            return {"box": (self.min, self.max)}
        return {"ball": (-np.inf, float(self.radius))}
