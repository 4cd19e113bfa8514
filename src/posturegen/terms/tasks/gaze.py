"""``gaze``: a frame's axis pointing at a world point (a camera looking at it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..nlp import ArrayLike
from .axis import orthonormal_pair
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


@register_task
@dataclass
class GazeTask(Task):
    """The point in the frame, v = R_world_frameᵀ (target - p_world_frame), lies along the
    frame's ``axis`` a: rows (u·v, w·v) / ‖v‖ = 0 for u, w orthogonal to a (sines of the angle
    between the axis and the line of sight), and a·v >= 0 (looking at it, not away)."""

    kind: ClassVar[str] = "gaze"
    unit: ClassVar[str] = "(sine)"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame (a camera's optical frame, a head link)"),
        "target": Field("vector", "[m] the world point looked at"),
        "axis": Field(
            "direction",
            "the frame's line of sight, in the frame",
            default=np.array([1.0, 0.0, 0.0]),
        ),
    }

    frame: str
    target: np.ndarray  # (3,) [m]
    axis: np.ndarray  # (3,) unit

    def target_point(self) -> np.ndarray | None:
        return np.asarray(self.target, dtype=float)

    def errors(self, f: Frames) -> dict[str, Expr]:
        R, p = f.placement(self.frame)
        v = R.T @ (f.param("target", self.target) - p)
        u, w = orthonormal_pair(np.asarray(self.axis))
        distance = f.norm(v)
        return {
            "gaze": f.vertcat(f.dot(f.param("u", u), v), f.dot(f.param("w", w), v)) / distance,
            "gaze_sense": f.dot(f.param("axis", self.axis), v),
        }

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        return {"gaze_sense": (0.0, np.inf)}

    def scales(self) -> dict[str, float]:
        return {"gaze_sense": 1.0}
