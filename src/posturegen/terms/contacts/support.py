"""``support``: a floating, force-bearing non-inclusive contact."""

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
from ..cop import DEFAULT_COP_MARGIN, declare_ellipse_cop, kappa_guess
from ..ellipse_options import EllipseOptions
from ..forces import declare_forces, force_guess, forces_dict, grip_parameter
from ..friction import FrictionModel
from ..nlp import BuildContext, Instance
from . import values as V
from .base import Contact, ContactEntry, register_contact
from .ellipse import EllipseContact, read_ellipse_options


@register_contact
@dataclass
class SupportContact(EllipseContact):
    """A floating, force-bearing non-inclusive contact: forces at k points of the ellipse's
    boundary, p_i = S⁻¹(c + R(θ)(rx cos t_i, ry sin t_i)), t_i = 2πi/k. The ellipse lies in
    both polygons, so these are true contact points."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    ellipse: EllipseOptions = field(default_factory=EllipseOptions)
    points: int = 8
    friction: FrictionModel = field(default_factory=FrictionModel)
    type: str = "support"
    cop_margin: float = field(default=DEFAULT_COP_MARGIN, kw_only=True)  # [m]
    grip: float = field(default=0.0, kw_only=True)  # [N] (posturegen.terms.forces)

    kind: ClassVar[str] = "support"
    keys: ClassVar[Mapping[str, V.Schema]] = {
        **V.ELLIPSE,
        "points": V.POINTS,
        "mu": V.MU,
        "friction": V.FRICTION,
        "yaw_range": V.YAW_RANGE,
        "cop_margin": V.COP_MARGIN,
        "grip": V.GRIP,
    }

    def __post_init__(self) -> None:
        if self.points < 4:
            raise InputError(f"contacts[{self.name}].points", f"{self.points} < 4", "use 4 to 16")
        self._init_scaling()

    def force_points_count(self) -> int:
        return self.points

    def key(self) -> tuple[Any, ...]:
        return (
            "support",
            self.name,
            self.patch.name,
            self.surface.polygon.n,
            self.ellipse,
            self.scaled,
            self.points,
            self.friction,
            self.cop_margin > 0,
            self.grip > 0,
            *self._plane_key(),
        )

    def declare(self, ctx: BuildContext) -> None:
        Rs, ps, V, _, _ = self._declare_plane(ctx)
        e, B = self._declare_ellipse(ctx, V)
        Sinv = ca.inv(ca.reshape(ctx.nlp.p[f"contact.{self.name}.scaling"], 2, 2))
        c, s = ca.cos(e[2]), ca.sin(e[2])
        points = []
        for i in range(self.points):
            t = 2 * np.pi * i / self.points
            lx, ly = e[3] * np.cos(t), e[4] * np.sin(t)
            q2 = Sinv @ ca.vertcat(e[0] + c * lx - s * ly, e[1] + s * lx + c * ly)
            points.append(ps + Rs @ ca.vertcat(q2, 0))
        pre = f"contact.{self.name}"
        phi_n = declare_forces(
            ctx, pre, self.patch.joint_id, points, self.friction, Rs, self.grip > 0
        )
        if self.cop_margin > 0:
            t = 2 * np.pi * np.arange(self.points) / self.points
            radii = None if self.scaled else e[3:5]
            declare_ellipse_cop(ctx.nlp, pre, phi_n, t, B, radii)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {
            **self._plane_parameters(),
            **self._ellipse_parameters(),
            f"contact.{self.name}.mu": np.array([self.mu]),
        }
        if self.grip > 0:
            weight = problem.robot.weight
            out[f"contact.{self.name}.grip"] = grip_parameter(self.grip, weight, self.points)
        if self.cop_margin > 0:
            out[f"contact.{self.name}.cop_margin"] = np.array([self.cop_margin])
        return out

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        out = {
            f"{pre}.ellipse": self._ellipse_guess(problem),
            f"{pre}.forces": force_guess(problem, self.points),
        }
        if self.cop_margin > 0:
            out[f"{pre}.cop_kappa"] = np.array([kappa_guess(self.cop_margin, self._min_radii()[0])])
        return out

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        out = self._base_dict()
        out["ellipse"] = self._ellipse_dict(outputs)
        out["forces"] = forces_dict(self.patch.frame, outputs, f"contact.{self.name}")
        out["cop_margin"] = self.cop_margin
        if self.grip > 0:
            out["grip"] = self.grip
        return out

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        k = common
        n = F.integer(entry.get("points", 8), f"{fld}.points", 4, "use 8")
        ell = read_ellipse_options(entry, fld)
        return cls(
            k.name,
            k.patch,
            k.surface,
            k.mu,
            ell,
            n,
            k.friction,
            yaw_range=k.yaw_range,
            cop_margin=k.cop_margin,
            grip=k.grip,
        )
