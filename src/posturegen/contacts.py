"""Contacts between a robot patch and a scene surface. A contact owns its variables (forces,
ellipse) and its constraints.

Frames: the surface frame s has z = the surface's outward normal; the robot patch frame c has
z = the patch's outward normal. In contact the normals are opposite, so a patch at in-plane
position (x, y) and yaw ψ on the surface is ``T_s_c = Trans(x, y, 0)·Rz(ψ)·Rx(π)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from .errors import InputError
from .geometry import ConvexPolygon, intersect
from .problem import BuildContext, Problem, Term
from .robot import Patch
from .scene import Surface


def patch_in_surface(position: np.ndarray, yaw: float) -> pin.SE3:
    """T_surface_patch = Trans(x, y, 0)·Rz(ψ)·Rx(π) (normals opposite)."""
    R = pin.utils.rotate("z", yaw) @ pin.utils.rotate("x", np.pi)
    return pin.SE3(R, np.array([position[0], position[1], 0.0]))


def polygon_in_surface(patch: Patch, T_surface_patch: pin.SE3) -> ConvexPolygon:
    """The robot patch's polygon expressed in the surface plane (2-D)."""
    v = patch.polygon.vertices
    pts = (
        np.column_stack([v, np.zeros(len(v))]) @ T_surface_patch.rotation.T
        + T_surface_patch.translation
    )
    return ConvexPolygon(pts[:, :2])


@dataclass(frozen=True)
class FrictionModel:
    """Friction cone |f_t| <= μ f_n, exactly (``cone``) or as an inscribed pyramid with
    ``faces`` faces: (cos θ_k, sin θ_k)·f_t <= μ cos(π/faces) f_n."""

    kind: str = "pyramid"  # "pyramid" | "cone"
    faces: int = 4

    def constraints(self, phi: ca.SX, mu: ca.SX) -> ca.SX:
        """Rows that must be <= 0 for local force φ = (f_t, f_n) (3,)."""
        if self.kind == "cone":
            return ca.vertcat(phi[0] ** 2 + phi[1] ** 2 - mu**2 * phi[2] ** 2)
        rows = []
        for k in range(self.faces):
            th = 2 * np.pi * k / self.faces
            rows.append(
                np.cos(th) * phi[0] + np.sin(th) * phi[1] - mu * np.cos(np.pi / self.faces) * phi[2]
            )
        return ca.vertcat(*rows)


class Contact(Term):
    """A robot patch against a scene surface."""

    type: str
    name: str
    patch: Patch
    surface: Surface
    mu: float

    def force_points_world(self) -> int:
        """Number of force-bearing points (0 for geometric contacts)."""
        return 0

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        """The posture file's entry for this contact, from the solution's outputs."""
        raise NotImplementedError


def declare_patch_frame(ctx: BuildContext, patch: Patch) -> tuple[ca.SX, ca.SX]:
    """(R_world_patch (3,3), p_world_patch (3,)) as expressions of q."""
    R_j, p_j = ctx.state.R[patch.joint_id], ctx.state.p[patch.joint_id]
    T = patch.T_joint_patch
    return R_j @ T.rotation, p_j + R_j @ T.translation


@dataclass
class FixedContact(Contact):
    """A robot patch at a given pose on a surface, bearing forces at the vertices of the
    intersection of the two polygons (paper sec. IV-E).

    Pose: ``R_tᵀ(p_c - p_t) = 0`` and the three skew components of ``R_tᵀR_c`` vanish, with
    ``T_t = T_world_surface·T_surface_patch`` the target. Forces: one f = W·R_s·φ per point,
    φ_n >= 0 and the friction model on φ, W the robot's weight.
    """

    name: str
    patch: Patch
    surface: Surface
    position: np.ndarray  # (2,) patch origin in the surface plane [m]
    yaw: float  # [rad]
    mu: float
    friction: FrictionModel = field(default_factory=FrictionModel)
    type: str = "fixed"

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

    def force_points_world(self) -> int:
        return self.n_points

    def key(self) -> tuple[Any, ...]:
        return ("fixed", self.name, self.patch.name, self.n_points, self.friction)

    def declare(self, ctx: BuildContext) -> None:
        nlp, k = ctx.nlp, self.n_points
        pre = f"contact.{self.name}"
        R_c, p_c = declare_patch_frame(ctx, self.patch)
        Rt = ca.reshape(nlp.parameter(f"{pre}.R_target", 9), 3, 3)
        pt = nlp.parameter(f"{pre}.p_target", 3)
        E = Rt.T @ R_c
        nlp.constrain(f"{pre}.position", Rt.T @ (p_c - pt), 0.0, 0.0)
        nlp.constrain(f"{pre}.orientation", ca.vertcat(E[2, 0], E[2, 1], E[1, 0]), 0.0, 0.0)
        # forces, scaled by the weight, in the surface frame
        phi = nlp.variable(f"{pre}.forces", 3 * k, np.tile([-np.inf, -np.inf, 0.0], k), np.inf)
        Rs = ca.reshape(nlp.parameter(f"{pre}.R_surface", 9), 3, 3)
        mu = nlp.parameter(f"{pre}.mu", 1)
        pts = ca.reshape(nlp.parameter(f"{pre}.points_joint", 3 * k), 3, k)
        W = ctx.robot.weight
        R_j, p_j = ctx.state.R[self.patch.joint_id], ctx.state.p[self.patch.joint_id]
        fric, p_world, f_world = [], [], []
        for i in range(k):
            phi_i = phi[3 * i : 3 * i + 3]
            fric.append(self.friction.constraints(phi_i, mu))
            pw = p_j + R_j @ pts[:, i]
            fw = W * (Rs @ phi_i)
            ctx.force_points.append((self.patch.joint_id, pw, fw))
            p_world.append(pw)
            f_world.append(fw)
        nlp.constrain(f"{pre}.friction", ca.vertcat(*fric), -np.inf, 0.0)
        nlp.output(f"{pre}.points", ca.horzcat(*p_world))
        nlp.output(f"{pre}.forces", ca.horzcat(*f_world))

    def parameters(self, problem: Problem) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        return {
            f"{pre}.R_target": self.T_world_target.rotation,
            f"{pre}.p_target": self.T_world_target.translation,
            f"{pre}.R_surface": self.surface.T_world_surface.rotation,
            f"{pre}.mu": np.array([self.mu]),
            f"{pre}.points_joint": self.points_joint.T,
        }

    def initial_guess(self, problem: Problem) -> dict[str, np.ndarray]:
        # share the weight evenly over every force point of every contact, along the normal
        total = sum(c.force_points_world() for c in problem.contacts) or 1
        phi = np.tile([0.0, 0.0, 1.0 / total], self.n_points)
        return {f"contact.{self.name}.forces": phi}

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        pre = f"contact.{self.name}"
        pts = outputs[f"{pre}.points"].reshape(3, -1, order="F").T
        fs = outputs[f"{pre}.forces"].reshape(3, -1, order="F").T
        return {
            "name": self.name,
            "type": self.type,
            "mu": self.mu,
            "pose": {"position": self.position.tolist(), "yaw": self.yaw},
            "robot_patch": {
                "name": self.patch.name,
                "frame": self.patch.frame,
                "placement": self.patch.T_frame_patch.homogeneous.tolist(),
                "vertices": self.patch.polygon.vertices.tolist(),
            },
            "surface": self.surface.to_dict(),
            "ellipse": None,
            "forces": [
                {"frame": self.patch.frame, "point": p.tolist(), "force": f.tolist()}
                for p, f in zip(pts, fs, strict=True)
            ],
        }
