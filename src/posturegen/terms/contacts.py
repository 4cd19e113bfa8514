"""Contacts between a robot patch and a scene surface. A contact owns its variables (forces,
ellipse) and its constraints.

Frames: the surface frame s has z = the surface's outward normal; the robot patch frame c has
z = the patch's outward normal. In contact the normals are opposite, so a patch at in-plane
position (x, y) and yaw ψ on the surface is ``T_s_c = Trans(x, y, 0)·Rz(ψ)·Rx(π)``.
"""

from __future__ import annotations

import dataclasses
from abc import abstractmethod
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..model.ellipse_rows import ellipse_edge_constraints_paper, ellipse_edge_constraints_support
from ..model.geometry import ConvexPolygon, intersect
from ..model.min_ellipse import default_min_radii
from ..model.robot import Patch
from ..model.scene import Surface
from .cop import (
    DEFAULT_COP_MARGIN,
    check_polygon_margin,
    declare_ellipse_cop,
    declare_polygon_cop,
    kappa_guess,
    polygon_depths,
)
from .ellipse_options import EllipseOptions, thin_scaling
from .forces import declare_forces, force_guess, forces_dict
from .friction import FrictionModel
from .nlp import BuildContext, Instance, Term


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


class Contact(Term):
    """A robot patch against a scene surface."""

    type: str
    name: str
    patch: Patch
    surface: Surface
    mu: float

    def force_points_count(self) -> int:
        """Number of force-bearing points (0 for contacts that bear no force)."""
        return 0

    def fingerprint(self) -> tuple[Any, ...]:
        """The key (which names the patch) and the patch's geometry, which the declaration
        reads: its joint, its placement on it and its polygon."""
        patch = self.patch
        return (*self.key(), patch.joint_id, patch.T_joint_patch, patch.polygon.vertices)

    @abstractmethod
    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        """The posture file's entry for this contact, from the solution's outputs."""

    def _base_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "type": self.type,
            "mu": self.mu,
            "robot_patch": {
                "name": self.patch.name,
                "frame": self.patch.frame,
                "placement": self.patch.T_frame_patch.homogeneous.tolist(),
                "vertices": self.patch.polygon.vertices.tolist(),
            },
            "surface": self.surface.to_dict(),
            "ellipse": None,
            "forces": [],
        }


def declare_patch_frame(ctx: BuildContext, patch: Patch) -> tuple[ca.SX, ca.SX]:
    """(R_world_patch (3,3), p_world_patch (3,)) as expressions of q."""
    R_j, p_j = ctx.state.R[patch.joint_id], ctx.state.p[patch.joint_id]
    T = patch.T_joint_patch
    return R_j @ T.rotation, p_j + R_j @ T.translation


@dataclass
class FixedContact(Contact):
    """A robot patch at a given pose on a surface, bearing forces at the vertices of the
    intersection of the two polygons (paper sec. IV-E).

    Pose: ``R_tᵀ(p_c - p_t) = 0``; E = R_tᵀR_c has E[2,0] = E[2,1] = E[1,0] = 0 and
    trace(E) >= 0 (the equalities alone also admit the rotations by π about x, y or z, of
    trace -1), with ``T_t = T_world_surface·T_surface_patch`` the target. Forces: one
    f = W·R_s·φ per point, φ_n >= 0 and the friction model on φ, W the robot's weight; the
    centre of pressure ``cop_margin`` [m] inside the intersection (:mod:`posturegen.terms.cop`).
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
        return self.n_points

    def key(self) -> tuple[Any, ...]:
        cop = self.cop_margin > 0
        return ("fixed", self.name, self.patch.name, self.n_points, self.friction, cop)

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
        pts = ca.reshape(nlp.parameter(f"{pre}.points_joint", 3 * k), 3, k)
        R_j, p_j = ctx.state.R[self.patch.joint_id], ctx.state.p[self.patch.joint_id]
        points = [p_j + R_j @ pts[:, i] for i in range(k)]
        Rs = ca.reshape(nlp.parameter(f"{pre}.R_surface", 9), 3, 3)
        phi_n = declare_forces(ctx, pre, self.patch.joint_id, points, self.friction, Rs)
        if self.cop_margin > 0:
            declare_polygon_cop(nlp, pre, phi_n, self.area.n)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        out = {
            f"{pre}.R_target": self.T_world_target.rotation,
            f"{pre}.p_target": self.T_world_target.translation,
            f"{pre}.R_surface": self.surface.T_world_surface.rotation,
            f"{pre}.mu": np.array([self.mu]),
            f"{pre}.points_joint": self.points_joint.T,
        }
        if self.cop_margin > 0:
            out[f"{pre}.cop_depths"] = polygon_depths(self.area, self.area.vertices)
            out[f"{pre}.cop_margin"] = np.array([self.cop_margin])
        return out

    def initial_guess(self, problem: Instance) -> dict[str, np.ndarray]:
        return {f"contact.{self.name}.forces": force_guess(problem, self.n_points)}

    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        out = self._base_dict()
        out["pose"] = {"position": self.position.tolist(), "yaw": self.yaw}
        out["cop_margin"] = self.cop_margin
        out["forces"] = forces_dict(self.patch.frame, outputs, f"contact.{self.name}")
        return out


# --------------------------------------------------------------------------- floating contacts
@dataclass
class FloatingContact(Contact):
    """A robot patch on a surface plane, free to slide and turn in it (paper eq. 2):
    (O_c - O_s)·N_s = 0, T_c·N_s = 0, B_c·N_s = 0, N_c·N_s <= 0.

    ``yaw_range`` = (ψ_min, ψ_max) [rad] bounds its yaw ψ in the surface frame (the angle of
    the patch's x axis, as for a fixed contact) by one smooth row, cos(ψ - ψ_mid) >= cos(ψ_half):
    (cos ψ_mid, sin ψ_mid)·(R_sc[0,0], R_sc[1,0]) >= cos ψ_half."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    yaw_range: tuple[float, float] | None = field(default=None, kw_only=True)

    def _plane_key(self) -> tuple[Any, ...]:
        """The structure this base adds to a subclass's key."""
        return ("yaw_range", self.yaw_range is not None)

    def _base_dict(self) -> dict[str, Any]:
        out = super()._base_dict()
        if self.yaw_range is not None:
            out["yaw_range"] = [float(v) for v in self.yaw_range]
        return out

    def _declare_plane(self, ctx: BuildContext) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """Coplanarity rows; returns (R_ws (3,3), p_ws (3,), patch vertices in the surface
        plane (n, 2) counter-clockwise, R_sc = R_wsᵀR_wc (3,3), p_sc (3,))."""
        nlp = ctx.nlp
        pre = f"contact.{self.name}"
        R_c, p_c = declare_patch_frame(ctx, self.patch)
        Rs = ca.reshape(nlp.parameter(f"{pre}.R_surface", 9), 3, 3)
        ps = nlp.parameter(f"{pre}.p_surface", 3)
        E = Rs.T @ R_c
        d = Rs.T @ (p_c - ps)
        nlp.constrain(f"{pre}.coplanarity", ca.vertcat(d[2], E[2, 0], E[2, 1]), 0.0, 0.0)
        nlp.constrain(f"{pre}.normals_opposite", E[2, 2], -np.inf, 0.0)
        if self.yaw_range is not None:
            yr = nlp.parameter(f"{pre}.yaw_range", 3)  # cos ψ_mid, sin ψ_mid, cos ψ_half
            nlp.constrain(
                f"{pre}.yaw_range", yr[0] * E[0, 0] + yr[1] * E[1, 0] - yr[2], 0.0, np.inf
            )
        v = self.patch.polygon.vertices
        # patch vertices in the surface plane; the flip of the normal reverses the orientation
        rows = [d[:2] + E[:2, :2] @ v[i] for i in reversed(range(len(v)))]
        return Rs, ps, ca.horzcat(*rows).T, E, d

    def _plane_parameters(self) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        out = {
            f"{pre}.R_surface": self.surface.T_world_surface.rotation,
            f"{pre}.p_surface": self.surface.T_world_surface.translation,
        }
        if self.yaw_range is not None:
            lo, hi = self.yaw_range
            mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            out[f"{pre}.yaw_range"] = np.array([np.cos(mid), np.sin(mid), np.cos(half)])
        return out

    def _surface_halfplanes(self, ctx: BuildContext) -> tuple[ca.SX, ca.SX]:
        """Parameters: outward unit normals (n, 2) and offsets (n,) of the surface polygon."""
        n = self.surface.polygon.n
        hp = ca.reshape(ctx.nlp.parameter(f"contact.{self.name}.surface_halfplanes", 3 * n), 3, n)
        return hp[0:2, :].T, hp[2, :].T

    def _halfplane_parameters(self) -> dict[str, np.ndarray]:
        normals, offsets = self.surface.polygon.halfplanes()
        return {f"contact.{self.name}.surface_halfplanes": np.vstack([normals.T, offsets])}

    def realized_pose(self, model: pin.Model, posture_q: np.ndarray) -> tuple[np.ndarray, float]:
        """(position (2,), yaw) of the patch in the surface frame at configuration q."""
        data = model.createData()
        pin.framesForwardKinematics(model, data, posture_q)
        T_sc = self.surface.T_world_surface.inverse() * data.oMf[self.patch.frame_id]
        T_sc = T_sc * self.patch.T_frame_patch
        return T_sc.translation[:2].copy(), float(
            np.arctan2(T_sc.rotation[1, 0], T_sc.rotation[0, 0])
        )


class _EllipseContact(FloatingContact):
    """A floating contact with the ellipse variables (x, y, θ, rx, ry) of sec. IV-C, in the
    surface plane scaled by S (sec. IV-F): the real ellipse is S⁻¹·E'."""

    ellipse: EllipseOptions

    def _init_scaling(self) -> None:
        """S (2, 2) of sec. IV-F for this surface, whether it is not the identity, and the
        default minimum radii when none are given."""
        if self.ellipse.min_radii is None:
            radii = default_min_radii(self.patch.polygon, self.surface.polygon)
            self.ellipse = dataclasses.replace(self.ellipse, min_radii=radii)
        self.S = thin_scaling(self.surface.polygon, self.ellipse.scaling)
        self.scaled = not np.allclose(self.S, np.eye(2))

    def _declare_ellipse(self, ctx: BuildContext, patch_vertices: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Ellipse variables and the card(P1) + card(P2) inclusion rows; returns e (5,) and
        the real ellipse's B = S⁻¹·R(θ)·diag(rx, ry) (2, 2)."""
        nlp, pre = ctx.nlp, f"contact.{self.name}"
        r_lo, r_hi = self._min_radii()
        # unscaled plane: the radii are the real semi-axes, so the minimums are plain bounds
        # (exact up to the labelling, which θ makes free); scaled: eigenvalue rows below
        lb_r = (r_hi, r_lo) if not self.scaled else (1e-4, 1e-4)
        e = nlp.variable(f"{pre}.ellipse", 5, [-np.inf, -np.inf, -np.inf, *lb_r], np.inf)
        S = ca.reshape(nlp.parameter(f"{pre}.scaling", 4), 2, 2)
        n_s = self.surface.polygon.n
        Vs = ca.reshape(nlp.parameter(f"{pre}.surface_vertices", 2 * n_s), 2, n_s)
        build = {
            "paper": ellipse_edge_constraints_paper,
            "support": ellipse_edge_constraints_support,
        }[self.ellipse.formulation]
        surf_scaled = (S @ Vs).T
        patch_scaled = (S @ patch_vertices.T).T
        rows = build(surf_scaled, *[e[i] for i in range(5)])
        rows += build(patch_scaled, *[e[i] for i in range(5)])
        nlp.constrain(f"{pre}.ellipse_inside", ca.vertcat(*rows), -np.inf, 0.0)
        # the real ellipse: B = S⁻¹·R(θ)·diag(rx, ry); M = BᵀB has eigenvalues σ1² >= σ2²
        Sinv = ca.inv(S)
        c, s = ca.cos(e[2]), ca.sin(e[2])
        R = ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))
        B = Sinv @ R @ ca.diag(ca.vertcat(e[3], e[4]))
        M = B.T @ B
        rows = []
        if self.scaled:
            # eigenvalues σ2² <= σ1² of M, smoothed by ε so that a round ellipse is no
            # singularity; both estimates are conservative (σ2²' <= σ2², σ1²' <= σ1²)
            half_tr = 0.5 * (M[0, 0] + M[1, 1])
            dev2 = 0.25 * (M[0, 0] - M[1, 1]) ** 2 + M[0, 1] ** 2
            eps_lo, eps_hi = (0.05 * r_lo**2) ** 2, (0.05 * r_hi**2) ** 2
            rows.append((half_tr - ca.sqrt(dev2 + eps_lo)) / r_lo**2 - 1.0)
            if r_hi > r_lo:
                rows.append((half_tr + ca.sqrt(dev2 + eps_hi) - np.sqrt(eps_hi)) / r_hi**2 - 1.0)
        area = np.pi * e[3] * e[4] / ca.det(S)  # real area [m²]
        if self.ellipse.min_area > 0:
            rows.append(area / self.ellipse.min_area - 1.0)
        if rows:
            nlp.constrain(f"{pre}.ellipse_size", ca.vertcat(*rows), 0.0, np.inf)
        if self.ellipse.maximize_area > 0:
            a_min = min(self.surface.polygon.area, self.patch.polygon.area)
            nlp.minimize(f"{pre}.area", -self.ellipse.maximize_area * area / a_min)
        nlp.output(f"{pre}.ellipse", e)
        nlp.output(f"{pre}.ellipse_B", B)
        return e, B

    def _min_radii(self) -> tuple[float, float]:
        """(smaller, larger) minimum semi-axis [m]."""
        lo, hi = sorted(self.ellipse.min_radii or (0.0, 0.0))
        return lo, hi

    def _ellipse_parameters(self) -> dict[str, np.ndarray]:
        pre = f"contact.{self.name}"
        return {
            f"{pre}.scaling": self.S,
            f"{pre}.surface_vertices": self.surface.polygon.vertices.T,
        }

    def _ellipse_guess(self, problem: Instance) -> np.ndarray:
        """Start inside the surface at the point nearest to the patch's initial position, with
        small radii, in the scaled plane."""
        p, yaw = self.realized_pose(problem.robot.model, problem.q_init)
        poly = self.surface.polygon
        centre = np.asarray(p, dtype=float)
        if not poly.contains(centre[None])[0]:
            centre = poly.centroid
        # a real ellipse slightly above the minimum radii, aligned with the scaling's axes
        lam, U = np.linalg.eigh(self.S)  # eigenvalues (1, k) or (k, 1)
        major = U[:, int(np.argmin(lam))]
        r_lo, r_hi = self._min_radii()
        Sc = self.S @ centre
        theta = float(np.arctan2(major[1], major[0]))
        return np.array([Sc[0], Sc[1], theta, 1.2 * r_hi, 1.1 * r_lo * float(lam.max())])

    def _ellipse_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        pre = f"contact.{self.name}"
        e = outputs[f"{pre}.ellipse"]
        B = outputs[f"{pre}.ellipse_B"].reshape(2, 2, order="F")
        U, sig, _ = np.linalg.svd(B)
        c2 = np.linalg.solve(self.S, e[:2])
        T = self.surface.T_world_surface
        centre = T.rotation @ np.array([c2[0], c2[1], 0.0]) + T.translation
        axes = [(T.rotation @ np.array([U[0, i], U[1, i], 0.0]) * sig[i]).tolist() for i in (0, 1)]
        return {
            "center": centre.tolist(),
            "axes": axes,
            "radii": sig.tolist(),
            "angle_in_surface": float(np.arctan2(U[1, 0], U[0, 0])),
            "center_in_surface": c2.tolist(),
            "formulation": self.ellipse.formulation,
            "min_radii": sorted(self._min_radii(), reverse=True),
            "min_area": self.ellipse.min_area,
        }


@dataclass
class GeometricContact(_EllipseContact):
    """The paper's non-inclusive contact: bears no force; an ellipse lies in both polygons."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    ellipse: EllipseOptions = field(default_factory=EllipseOptions)
    type: str = "geometric"

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


@dataclass
class SupportContact(_EllipseContact):
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
        phi_n = declare_forces(ctx, pre, self.patch.joint_id, points, self.friction, Rs)
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
        return out


@dataclass
class InclusiveContact(FloatingContact):
    """Baseline: every vertex of the robot patch inside the surface polygon,
    card(P1)·card(P2) rows n_k·v_i <= b_k; bears no force."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    type: str = "inclusive"

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
