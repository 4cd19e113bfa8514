"""The non-inclusive contacts' shared base (geometric and support): the ellipse variables
(x, y, θ, rx, ry) of the paper's sec. IV-C in both polygons, in the plane scaled by S (sec.
IV-F), and the reading of their ellipse options."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import casadi as ca
import numpy as np

from ... import _fields as F
from ...errors import InputError
from ...hints import with_hint
from ...model.ellipse_rows import ellipse_edge_constraints_paper, ellipse_edge_constraints_support
from ...model.min_ellipse import default_min_radii
from ..ellipse_options import EllipseOptions, thin_scaling
from ..nlp import BuildContext, Instance
from .floating import FloatingContact


class EllipseContact(FloatingContact):
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


def read_ellipse_options(c: Mapping[str, Any], fld: str) -> EllipseOptions:
    """A geometric or support contact's ellipse keys (defaults: :class:`EllipseOptions`)."""
    base = EllipseOptions()
    form = F.string(c.get("formulation", base.formulation), f"{fld}.formulation")
    if form not in ("paper", "support"):
        raise InputError(
            f"{fld}.formulation",
            f"unknown formulation '{form}'",
            with_hint(form, ("paper", "support"), "use paper or support"),
        )
    radii = base.min_radii
    if "min_radii" in c:
        r = F.vector(c["min_radii"], 2, f"{fld}.min_radii")
        if np.any(r <= 0):
            raise InputError(f"{fld}.min_radii", "radii must be positive", "write [rx, ry] > 0 (m)")
        radii = (float(r[0]), float(r[1]))
    scaling = c.get("scaling", base.scaling)
    if scaling not in ("auto", "none"):
        scaling = F.number(scaling, f"{fld}.scaling", positive=True)
    return EllipseOptions(
        formulation=form,
        min_radii=radii,
        min_area=F.number(c.get("min_area", 0.0), f"{fld}.min_area", minimum=0.0),
        maximize_area=F.number(c.get("maximize_area", 0.0), f"{fld}.maximize_area", minimum=0.0),
        scaling=scaling,
    )
