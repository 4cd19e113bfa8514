"""Centre-of-pressure margins: the centre of pressure (CoP) of a contact's forces kept at least
m [m] inside its contact region, so that a contact does not bear its load on an edge.

CoP = Σ f_n,i·p_i / Σ f_n,i over the contact's force points p_i (in the surface plane), f_n,i
their normal forces (φ_n,i = f_n,i / W in the program, W the robot's weight). The rows are
homogeneous in the forces: a contact that bears nothing meets them (it has no CoP).

- Fixed contact, forces at the vertices v_i of the intersection polygon (edges n_e·x <= b_e):
  n_e·CoP <= b_e - m for every edge, linear in the forces:
  Σ_i φ_n,i·((n_e·v_i - b_e)/m + 1) <= 0.
- Support contact, forces at p_i = c + B·(cos t_i, sin t_i) on the boundary of the real ellipse
  E = c + B·{|u| <= 1}: CoP = c + B·u with u = U/F, U = Σ φ_n,i·(cos t_i, sin t_i), F = Σ φ_n,i.
  The disc of radius m about the CoP is in E when m <= σ_min(B)·(1 - |u|) (support functions:
  n·Bu + m <= |Bᵀn|·|u| + m <= |Bᵀn| for every unit n). With a variable κ in [0, 1]:
  |U|² - κ²F² <= 0 (|u| <= κ, a cone like the exact friction cone) and (1-κ)·σ_min(B) >= m.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import InputError
from ..model.geometry import ConvexPolygon
from ..model.min_ellipse import inscribed_disc
from .nlp import NLP

# [m] Default CoP margin of every force-bearing contact (options.cop_margin): the placement
# accuracy of a position-controlled humanoid's hand or foot (a few mm at the end of a 0.7 m
# chain), as the 5 mm by which the patch files keep inside the robot's meshes; it leaves a
# 2.5 cm rung a 1.5 cm wide band for the CoP and a TALOS foot 90 % of its width.
DEFAULT_COP_MARGIN = 0.005


def polygon_depths(region: ConvexPolygon, points: np.ndarray) -> np.ndarray:
    """D (e, k) = n_e·p_i - b_e: each point's signed distance to each edge line of ``region``
    [m] (<= 0 inside), for points (k, 2) in the region's plane."""
    normals, offsets = region.halfplanes()
    return normals @ np.asarray(points, dtype=float).T - offsets[:, None]


def check_polygon_margin(region: ConvexPolygon, margin: float, patch: str, surface: str) -> None:
    """An InputError when a fixed contact's intersection polygon has no point ``margin`` [m]
    inside it (its inradius is smaller): the contact could bear no force."""
    width = 2 * inscribed_disc(region)[1]
    if margin > 0 and width < 2 * margin:
        raise InputError(
            "cop_margin",
            f"patch '{patch}' overlaps surface '{surface}' by a region {100 * width:.2g} cm "
            f"wide, less than twice the CoP margin ({100 * margin:.2g} cm): it could bear no force",
            "move the contact further onto the surface, or lower cop_margin",
        )


def declare_polygon_cop(nlp: NLP, pre: str, phi_n: ca.SX, n_edges: int) -> None:
    """Rows ``{pre}.cop`` (n_edges,) <= 0: Σ_i φ_n,i·(D[e, i]/m + 1), with the parameters
    ``{pre}.cop_depths`` D (n_edges, k) (:func:`polygon_depths` of the force points) and
    ``{pre}.cop_margin`` m [m]; φ_n (k,) the normal forces over the weight."""
    k = phi_n.shape[0]
    D = ca.reshape(nlp.parameter(f"{pre}.cop_depths", n_edges * k), n_edges, k)
    m = nlp.parameter(f"{pre}.cop_margin", 1)
    nlp.constrain(f"{pre}.cop", D @ phi_n / m + ca.sum1(phi_n), -np.inf, 0.0)


def declare_ellipse_cop(
    nlp: NLP, pre: str, phi_n: ca.SX, angles: np.ndarray, B: ca.SX, radii: ca.SX | None
) -> None:
    """The variable ``{pre}.cop_kappa`` κ in [0, 1] and the rows ``{pre}.cop`` (1,) <= 0:
    |U|² - κ²F², and ``{pre}.cop_radius`` >= 0: (1-κ)·r/m - 1 for r in ``radii`` (the real
    semi-axes (2,), when the plane is not scaled, σ_min(B) = min(rx, ry)), else
    (1-κ)²·λ/m² - 1 with λ = tr(M)/2 - sqrt(((M00 - M11)/2)² + M01² + (0.05·m²)²) <= σ_min(B)²,
    M = BᵀB (2, 2). φ_n (k,) the normal forces over the weight at the boundary angles t_i."""
    kappa = nlp.variable(f"{pre}.cop_kappa", 1, 0.0, 1.0)
    m = nlp.parameter(f"{pre}.cop_margin", 1)
    U = ca.vertcat(ca.dot(np.cos(angles), phi_n), ca.dot(np.sin(angles), phi_n))
    F = ca.sum1(phi_n)
    nlp.constrain(f"{pre}.cop", ca.sumsqr(U) - kappa**2 * F**2, -np.inf, 0.0)
    if radii is not None:
        rows = [(1 - kappa) * radii[i] / m - 1.0 for i in range(2)]
    else:
        M = B.T @ B
        dev2 = 0.25 * (M[0, 0] - M[1, 1]) ** 2 + M[0, 1] ** 2
        lam = 0.5 * (M[0, 0] + M[1, 1]) - ca.sqrt(dev2 + (0.05 * m**2) ** 2)
        rows = [(1 - kappa) ** 2 * lam / m**2 - 1.0]
    nlp.constrain(f"{pre}.cop_radius", ca.vertcat(*rows), 0.0, np.inf)


def kappa_guess(margin: float, radius: float) -> float:
    """An initial κ halfway into [0, 1 - m/r], r the ellipse's smallest initial radius."""
    return 0.5 * max(0.0, 1.0 - margin / radius)
