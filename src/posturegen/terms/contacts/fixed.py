"""``fixed``: a robot patch at a given pose on a surface, bearing forces at the vertices of
the intersection (the paper's sec. IV-E)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np
import pinocchio as pin

from ... import _fields as F
from ...errors import InputError
from ...model.geometry import intersect
from ...model.robot import Patch
from ...model.scene import Surface
from ..cop import DEFAULT_COP_MARGIN, check_polygon_margin, declare_polygon_cop, polygon_depths
from ..forces import declare_forces, force_guess, forces_dict, grip_parameter
from ..friction import FrictionModel
from ..nlp import BuildContext, Instance
from . import values as V
from .base import (
    Contact,
    ContactEntry,
    declare_patch_frame,
    patch_in_surface,
    polygon_in_surface,
    register_contact,
)


@register_contact
@dataclass
class FixedContact(Contact):
    """A robot patch at a given pose on a surface, bearing forces at the vertices of the
    intersection of the two polygons (paper sec. IV-E).

    Pose: ``R_tᵀ(p_c - p_t) = 0``; E = R_tᵀR_c has E[2,0] = E[2,1] = E[1,0] = 0 and
    trace(E) >= 0 (the equalities alone also admit the rotations by π about x, y or z, of
    trace -1), with ``T_t = T_world_surface·T_surface_patch`` the target. Forces: one
    f = W·R_s·φ per point, φ_n >= 0 and the friction model on φ, W the robot's weight; the
    centre of pressure ``cop_margin`` [m] inside the intersection (:mod:`posturegen.terms.cop`);
    ``grip`` [N]: a hand closed around the surface (:mod:`posturegen.terms.forces`).

    ``unloaded``: the patch kept exactly where it is, bearing nothing (the pose rows only, no
    force variable): a contact about to be removed, while the others bear the weight.
    """

    name: str
    patch: Patch
    surface: Surface
    position: np.ndarray  # (2,) patch origin in the surface plane [m]
    yaw: float  # [rad]
    mu: float
    friction: FrictionModel = field(default_factory=FrictionModel)
    type: str = "fixed"
    cop_margin: float = field(default=DEFAULT_COP_MARGIN, kw_only=True)  # [m]
    unloaded: bool = field(default=False, kw_only=True)
    grip: float = field(default=0.0, kw_only=True)  # [N]

    kind: ClassVar[str] = "fixed"
    keys: ClassVar[Mapping[str, V.Schema]] = {
        "position": V.POSITION,
        "yaw": V.YAW,
        "mu": V.MU,
        "friction": V.FRICTION,
        "cop_margin": V.COP_MARGIN,
        "unloaded": V.UNLOADED,
        "grip": V.GRIP,
    }
    fixed_in_place: ClassVar[bool] = True

    def __post_init__(self) -> None:
        self.T_surface_patch = patch_in_surface(self.position, self.yaw)
        area = intersect(polygon_in_surface(self.patch, self.T_surface_patch), self.surface.polygon)
        if area is None:
            raise InputError(
                f"contacts[{self.name}]",
                f"patch '{self.patch.name}' does not overlap surface '{self.surface.name}' at "
                f"position {self.position.tolist()}",
                "move the contact's position inside the surface polygon",
            )
        self.area = area  # intersection polygon in the surface plane
        if not self.unloaded:  # an unloaded patch has no centre of pressure
            check_polygon_margin(area, self.cop_margin, self.patch.name, self.surface.name)
        # force points: the intersection's vertices, in the parent joint frame of the patch
        pts_s = np.column_stack([area.vertices, np.zeros(area.n)])
        T_joint_surface = self.patch.T_joint_patch * self.T_surface_patch.inverse()
        self.points_joint = (
            pts_s @ T_joint_surface.rotation.T + T_joint_surface.translation
        )  # (k, 3)
        self.T_world_target = self.surface.T_world_surface * self.T_surface_patch

    @property
    def n_points(self) -> int:
        """Number of force-bearing points."""
        return len(self.points_joint)

    def force_points_count(self) -> int:
        return 0 if self.unloaded else self.n_points

    def key(self) -> tuple[Any, ...]:
        if self.unloaded:
            return ("fixed", self.name, self.patch.name, "unloaded")
        cop = self.cop_margin > 0
        grip = self.grip > 0
        return ("fixed", self.name, self.patch.name, self.n_points, self.friction, cop, grip)

    def declare(self, ctx: BuildContext) -> None:
        nlp, k = ctx.nlp, self.n_points
        pre = f"contact.{self.name}"
        R_c, p_c = declare_patch_frame(ctx, self.patch)
        Rt = ca.reshape(nlp.parameter(f"{pre}.R_target", 9), 3, 3)
        pt = nlp.parameter(f"{pre}.p_target", 3)
        E = Rt.T @ R_c
        nlp.constrain(f"{pre}.position", Rt.T @ (p_c - pt), 0.0, 0.0)
        nlp.constrain(f"{pre}.orientation", ca.vertcat(E[2, 0], E[2, 1], E[1, 0]), 0.0, 0.0)
        # those rows also hold for E = Rz(π), Rx(π), Ry(π) (trace -1): keep the trace >= 0
        nlp.constrain(f"{pre}.orientation_branch", ca.trace(E), 0.0, np.inf)
        if self.unloaded:
            return
        pts = ca.reshape(nlp.parameter(f"{pre}.points_joint", 3 * k), 3, k)
        R_j, p_j = ctx.state.R[self.patch.joint_id], ctx.state.p[self.patch.joint_id]
        points = [p_j + R_j @ pts[:, i] for i in range(k)]
        Rs = ca.reshape(nlp.parameter(f"{pre}.R_surface", 9), 3, 3)
        phi_n = declare_forces(
            ctx, pre, self.patch.joint_id, points, self.friction, Rs, self.grip > 0
        )
        if self.cop_margin > 0:
            declare_polygon_cop(nlp, pre, phi_n, self.area.n)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        pose = {
            f"{pre}.R_target": self.T_world_target.rotation,
            f"{pre}.p_target": self.T_world_target.translation,
        }
        if self.unloaded:
            return pose
        out = {
            **pose,
            f"{pre}.R_surface": self.surface.T_world_surface.rotation,
            f"{pre}.mu": np.array([self.mu]),
            f"{pre}.points_joint": self.points_joint.T,
        }
        if self.grip > 0:
            out[f"{pre}.grip"] = grip_parameter(self.grip, problem.robot.weight, self.n_points)
        if self.cop_margin > 0:
            out[f"{pre}.cop_depths"] = polygon_depths(self.area, self.area.vertices)
            out[f"{pre}.cop_margin"] = np.array([self.cop_margin])
        return out

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        if self.unloaded:
            return {}
        return {f"contact.{self.name}.forces": force_guess(problem, self.n_points)}

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        out = self._base_dict()
        out["pose"] = {"position": self.position.tolist(), "yaw": self.yaw}
        out["cop_margin"] = self.cop_margin
        if self.grip > 0:
            out["grip"] = self.grip
        if self.unloaded:
            out["unloaded"] = True  # "forces": [] (bearing nothing)
            return out
        out["forces"] = forces_dict(self.patch.frame, outputs, f"contact.{self.name}")
        return out

    def realized_pose(self, model: pin.Model, q: np.ndarray) -> tuple[np.ndarray, float]:
        return np.asarray(self.position), float(self.yaw)  # realized to 1e-6 when verified

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        if "position" not in entry:
            raise InputError(
                f"{fld}.position",
                "missing for a fixed contact",
                "add position: [x, y] in the surface frame",
            )
        pos = F.vector(entry["position"], 2, f"{fld}.position")
        yaw = F.angle(entry.get("yaw", 0.0), f"{fld}.yaw")
        unloaded = entry.get("unloaded", False)
        if not isinstance(unloaded, bool):
            raise InputError(f"{fld}.unloaded", f"expected true or false, got {unloaded!r}", "")
        k = common
        try:
            return cls(
                k.name,
                k.patch,
                k.surface,
                pos,
                yaw,
                k.mu,
                k.friction,
                cop_margin=k.cop_margin,
                unloaded=unloaded,
                grip=k.grip,
            )
        except InputError as exc:
            raise InputError(
                f"{fld}.cop_margin" if exc.field == "cop_margin" else fld, exc.problem, exc.fix
            ) from exc
