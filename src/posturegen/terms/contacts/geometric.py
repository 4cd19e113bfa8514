"""``geometric``: the paper's non-inclusive contact, bearing no force."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ...model.robot import Patch
from ...model.scene import Surface
from ..ellipse_options import EllipseOptions
from ..nlp import BuildContext, Instance
from . import values as V
from .base import Contact, ContactEntry, register_contact
from .ellipse import EllipseContact, read_ellipse_options


@register_contact
@dataclass
class GeometricContact(EllipseContact):
    """The paper's non-inclusive contact: bears no force; an ellipse lies in both polygons."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    ellipse: EllipseOptions = field(default_factory=EllipseOptions)
    type: str = "geometric"

    kind: ClassVar[str] = "geometric"
    keys: ClassVar[Mapping[str, V.Schema]] = {**V.ELLIPSE, "yaw_range": V.YAW_RANGE}

    def __post_init__(self) -> None:
        self._init_scaling()

    def key(self) -> tuple[Any, ...]:
        return (
            "geometric",
            self.name,
            self.patch.name,
            self.surface.polygon.n,
            self.ellipse,
            self.scaled,
            *self._plane_key(),
        )

    def declare(self, ctx: BuildContext) -> None:
        V = self._declare_plane(ctx)[2]
        self._declare_ellipse(ctx, V)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        return {**self._plane_parameters(), **self._ellipse_parameters()}

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        return {f"contact.{self.name}.ellipse": self._ellipse_guess(problem)}

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        out = self._base_dict()
        out["ellipse"] = self._ellipse_dict(outputs)
        return out

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        k = common
        ell = read_ellipse_options(entry, fld)
        return cls(k.name, k.patch, k.surface, k.mu, ell, yaw_range=k.yaw_range)
