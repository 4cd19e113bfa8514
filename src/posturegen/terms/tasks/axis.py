"""``axis``: one axis of a frame along a world direction, or lying in a plane."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...errors import InputError
from ..nlp import ArrayLike
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


def orthonormal_pair(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) orthogonal to the unit d and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(d)))]
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


@register_task
@dataclass
class AxisTask(Task):
    """a = R_world_frame · axis (a unit vector of the frame, in world).

    With ``direction`` d: a along d, rows (u·a, v·a) = 0 for u, v orthogonal to d, and a·d >= 0
    (not against it); the rows are sines of the angle between a and d. With ``normal`` n: a in
    the plane of normal n, the row a·n = 0 (the sine of a's angle to the plane)."""

    kind: ClassVar[str] = "axis"
    unit: ClassVar[str] = "(sine)"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame"),
        "axis": Field("direction", "the frame's axis, in the frame (normalized)"),
        "direction": Field("direction", "the world direction the axis points along", default=None),
        "normal": Field(
            "direction", "the normal of the world plane the axis lies in", default=None
        ),
    }

    frame: str
    axis: np.ndarray  # (3,) unit, in the frame
    direction: np.ndarray | None = None  # (3,) unit, in world
    normal: np.ndarray | None = None  # (3,) unit, in world

    def check(self, fld: str) -> None:
        if (self.direction is None) == (self.normal is None):
            raise InputError(
                fld,
                "needs direction or normal (one of them)",
                "add direction: [x, y, z] (aligned) or normal: [x, y, z] (in plane)",
            )

    def errors(self, f: Frames) -> dict[str, Expr]:
        a = f.rotation(self.frame) @ f.param("axis", self.axis)
        if self.direction is not None:
            u, v = orthonormal_pair(np.asarray(self.direction))
            d = f.param("direction", self.direction)
            return {
                "alignment": f.vertcat(f.dot(f.param("u", u), a), f.dot(f.param("v", v), a)),
                "alignment_sense": f.dot(d, a),
            }
        return {"in_plane": f.dot(f.param("normal", self.normal), a)}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        return {"alignment_sense": (0.0, np.inf)}

    def scales(self) -> dict[str, float]:
        return {"alignment_sense": 1.0}
