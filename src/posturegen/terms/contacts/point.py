"""``point``: the baseline of one point of the patch inside the surface (a fingertip)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ... import _fields as F
from ...errors import InputError
from ...model.robot import Patch
from ...model.scene import Surface
from ..nlp import BuildContext, Instance
from . import values as V
from .base import Contact, ContactEntry, PlacedContact, points_in_plane, register_contact
from .floating import FloatingContact


@register_contact
@dataclass
class PointContact(FloatingContact):
    """Baseline: one given point of the robot patch (patch frame, default its origin) on the
    surface, inside its polygon (card(P2) rows), normals opposite; bears no force."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    point: np.ndarray = field(default_factory=lambda: np.zeros(2))
    type: str = "point"

    kind: ClassVar[str] = "point"
    keys: ClassVar[Mapping[str, V.Schema]] = {"point": V.POINT, "yaw_range": V.YAW_RANGE}

    def key(self) -> tuple[Any, ...]:
        return ("point", self.name, self.patch.name, self.surface.polygon.n, *self._plane_key())

    def declare(self, ctx: BuildContext) -> None:
        Rs, ps, _, E, d = self._declare_plane(ctx)
        local = ctx.nlp.parameter(f"contact.{self.name}.point", 2)
        q2 = d[:2] + E[:2, :2] @ local
        pw = ps + Rs @ ca.vertcat(q2, d[2])
        normals, offsets = self._surface_halfplanes(ctx)
        ctx.nlp.constrain(f"contact.{self.name}.point_inside", normals @ q2 - offsets, -np.inf, 0.0)
        ctx.nlp.output(f"contact.{self.name}.point_world", pw)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {
            **self._plane_parameters(),
            **self._halfplane_parameters(),
            f"contact.{self.name}.point": self.point,
        }

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        out = self._base_dict()
        out["point"] = {
            "patch": self.point.tolist(),
            "world": outputs[f"contact.{self.name}.point_world"].tolist(),
        }
        return out

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        k = common
        point = F.vector(entry.get("point", [0.0, 0.0]), 2, f"{fld}.point")
        if not k.patch.polygon.contains(point[None])[0]:
            raise InputError(
                f"{fld}.point",
                "the point is outside the robot patch",
                "give a point of the patch polygon, in the patch frame",
            )
        return cls(k.name, k.patch, k.surface, k.mu, point, yaw_range=k.yaw_range)

    @staticmethod
    def recheck_outside(entry: Mapping[str, Any], f: PlacedContact) -> float:
        """[m] how far the contact's point is outside the surface."""
        p_world = np.asarray(entry["point"]["world"], dtype=float)[None]
        return float(-f.P_s.distance_inside(points_in_plane(f.T_ws, p_world)[:, :2])[0])
