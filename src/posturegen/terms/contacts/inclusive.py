"""``inclusive``: the paper's baseline, every vertex of the patch inside the surface."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ...model.robot import Patch
from ...model.scene import Surface
from ..nlp import BuildContext, Instance
from . import values as V
from .base import Contact, ContactEntry, PlacedContact, points_in_plane, register_contact
from .floating import FloatingContact


@register_contact
@dataclass
class InclusiveContact(FloatingContact):
    """Baseline: every vertex of the robot patch inside the surface polygon,
    card(P1)·card(P2) rows n_k·v_i <= b_k; bears no force."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    type: str = "inclusive"

    kind: ClassVar[str] = "inclusive"
    keys: ClassVar[Mapping[str, V.Schema]] = {"yaw_range": V.YAW_RANGE}

    def key(self) -> tuple[Any, ...]:
        return ("inclusive", self.name, self.patch.name, self.surface.polygon.n, *self._plane_key())

    def declare(self, ctx: BuildContext) -> None:
        V = self._declare_plane(ctx)[2]
        normals, offsets = self._surface_halfplanes(ctx)
        rows = normals @ V.T - ca.repmat(offsets, 1, V.shape[0])  # (n_s, n_p)
        ctx.nlp.constrain(f"contact.{self.name}.inclusion", ca.vec(rows), -np.inf, 0.0)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {**self._plane_parameters(), **self._halfplane_parameters()}

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        return self._base_dict()

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        k = common
        return cls(k.name, k.patch, k.surface, k.mu, yaw_range=k.yaw_range)

    @staticmethod
    def recheck_outside(entry: Mapping[str, Any], f: PlacedContact) -> float:
        """[m] how far the patch's worst vertex is outside the surface."""
        v_c = np.column_stack([f.P_c.vertices, np.zeros(f.P_c.n)])
        v_w = v_c @ f.T_wc.rotation.T + f.T_wc.translation
        return float(-f.P_s.distance_inside(points_in_plane(f.T_ws, v_w)[:, :2]).min())
