"""The floating contacts' shared base: a patch on a surface plane, free to slide and turn in
it (the paper's eq. 2), with optional yaw bounds."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ...model.robot import Patch
from ...model.scene import Surface
from ..nlp import BuildContext
from .base import Contact, declare_patch_frame


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
