"""``com``: the centre of mass at a point, at a height, or over a region of the ground."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...errors import InputError
from ...model.geometry import ConvexPolygon
from ..nlp import ArrayLike
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


@register_task
@dataclass
class ComTask(Task):
    """c = the centre of mass in world [m]: c = target (3 rows), or c_z = height (1 row), or
    c's (x, y) inside a convex polygon by at least ``margin``: nᵢ·c_xy <= bᵢ - margin for each
    edge's outward normal nᵢ (a row per edge; the polygon is given in world, for example the
    hull of the feet)."""

    kind: ClassVar[str] = "com"
    fields: ClassVar[dict[str, Field]] = {
        "target": Field("vector", "[m] the centre of mass in world", default=None),
        "height": Field("number", "[m] the centre of mass' height in world", default=None),
        "polygon": Field(
            "points", "[m] [[x, y], ...] a convex region of the ground plane", default=None
        ),
        "margin": Field("number", "[m] how far inside the polygon", default=0.0, minimum=0.0),
    }

    target: np.ndarray | None = None
    height: float | None = None
    polygon: np.ndarray | None = None  # (k, 2)
    margin: float = 0.0

    def subject(self) -> str:
        return "com"

    def check(self, fld: str) -> None:
        given = [k for k in ("target", "height", "polygon") if getattr(self, k) is not None]
        if len(given) != 1:
            raise InputError(
                fld,
                "needs one of target, height or polygon",
                "add target: [x, y, z], height: z or polygon: [[x, y], ...]",
            )
        if self.polygon is not None:
            self.polygon = ConvexPolygon(self.polygon, f"{fld}.polygon").vertices

    def target_point(self) -> np.ndarray | None:
        return None if self.target is None else np.asarray(self.target, dtype=float)

    def errors(self, f: Frames) -> dict[str, Expr]:
        c = f.com()
        if self.target is not None:
            return {"com": c - f.param("target", self.target)}
        if self.height is not None:
            return {"com_height": c[2]}
        A, b = ConvexPolygon(self.polygon).halfplanes()  # A (k, 2) outward normals, b (k,)
        normals = f.param("normals", A.ravel())  # (2k,) [nx0, ny0, nx1, ...]
        offsets = f.param("offsets", b)  # (k,) [m]
        rows = [
            normals[2 * i] * c[0] + normals[2 * i + 1] * c[1] - offsets[i] for i in range(len(b))
        ]
        return {"com_support": f.vertcat(*rows)}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        if self.height is not None:
            return {"com_height": (self.height, self.height)}
        if self.polygon is not None:
            return {"com_support": (-np.inf, -self.margin)}
        return {}
