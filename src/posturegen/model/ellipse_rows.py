"""The inclusion of an ellipse in a convex polygon as one smooth row ``g_k <= 0`` per edge
(Brossette et al., IROS 2014, sec. IV): exactly as in the paper (eqs. 4-6,
:func:`ellipse_edge_constraints_paper`) or in the better-conditioned support-function form
(:func:`ellipse_edge_constraints_support`). Both take casadi ``SX``/``MX`` (or plain float)
arguments, so that the posture problem's contacts and :mod:`posturegen.model.ellipse_fit` share
them."""

from __future__ import annotations

from typing import Any

import casadi as ca

from ..errors import InputError
from .geometry import ConvexPolygon, PolygonLike, Scalar

__all__ = ["ellipse_edge_constraints_paper", "ellipse_edge_constraints_support"]

SUPPORT_EPS2 = 1e-12
"""Default smoothing ``eps2`` of the support-form constraint (squared length units)."""


def _vertex_rows(P: Any) -> list[tuple[Any, Any]]:  # noqa: ANN401
    """Vertices of ``P`` as ``(x, y)`` pairs: floats for numeric input, casadi for symbolic."""
    if isinstance(P, ConvexPolygon):
        return [(float(x), float(y)) for x, y in P.vertices]
    if isinstance(P, (ca.SX, ca.MX)):
        if P.size2() != 2 or P.size1() < 3:
            raise InputError("P", f"expected an (n, 2) casadi matrix, got {P.shape}", "")
        return [(P[i, 0], P[i, 1]) for i in range(P.size1())]
    return [(float(x), float(y)) for x, y in ConvexPolygon(P, field="P").vertices]


def ellipse_edge_constraints_paper(
    P: PolygonLike | ca.SX | ca.MX,
    cx: Scalar,
    cy: Scalar,
    theta: Scalar,
    rx: Scalar,
    ry: Scalar,
) -> list[Any]:
    """Paper eqs. (4)+(6): ``g_k = -(p_ip_j)_E x (p_iO_E)_E + ||(p_ip_j)_E|| <= 0`` per edge.

    A vector ``w`` is mapped to the ellipse frame by ``w_E = diag(1/rx, 1/ry) R(-theta) w`` (eq. 4),
    where the ellipse is the unit circle (``r_E = 1``).  ``P`` must be counter-clockwise (a
    :class:`ConvexPolygon` or numeric array is normalized; a casadi ``(n, 2)`` matrix is taken as
    is) so that ``g_k < 0`` for an ellipse strictly inside.  Equivalent to the support form:
    ``g_paper = g_support * |p_ip_j| / (rx ry)``, hence the same feasible set for ``rx, ry > 0``.
    """
    verts = _vertex_rows(P)
    c, s = ca.cos(theta), ca.sin(theta)
    out: list[Any] = []
    n = len(verts)
    for i in range(n):
        (xi, yi), (xj, yj) = verts[i], verts[(i + 1) % n]
        ex, ey = xj - xi, yj - yi  # p_i p_j in F_0
        ox, oy = cx - xi, cy - yi  # p_i O_E in F_0
        ex_e, ey_e = (c * ex + s * ey) / rx, (-s * ex + c * ey) / ry
        ox_e, oy_e = (c * ox + s * oy) / rx, (-s * ox + c * oy) / ry
        cross = ex_e * oy_e - ey_e * ox_e
        out.append(-cross + ca.sqrt(ex_e * ex_e + ey_e * ey_e) * 1.0)
    return out


def ellipse_edge_constraints_support(
    P: PolygonLike | ca.SX | ca.MX,
    cx: Scalar,
    cy: Scalar,
    theta: Scalar,
    rx: Scalar,
    ry: Scalar,
    eps2: float = SUPPORT_EPS2,
) -> list[Any]:
    """Support form ``g_k = n_k.c + sqrt(rx^2 (n_k.u)^2 + ry^2 (n_k.v)^2 + eps2) - b_k <= 0``.

    ``n_k`` is the outward unit normal of edge ``k`` of the counter-clockwise ``P`` and
    ``b_k = n_k . p_k``; ``u = (cos theta, sin theta)``, ``v = (-sin theta, cos theta)``.
    ``eps2 > 0`` keeps the square root smooth at ``rx = ry = 0``; since
    ``sqrt(s^2 + eps2) <= s + sqrt(eps2)`` it is conservative: it shrinks the feasible set by at
    most ``sqrt(eps2)`` (length units of the inputs), never enlarges it.
    """
    verts = _vertex_rows(P)
    c, s = ca.cos(theta), ca.sin(theta)
    out: list[Any] = []
    n = len(verts)
    for i in range(n):
        (xi, yi), (xj, yj) = verts[i], verts[(i + 1) % n]
        ex, ey = xj - xi, yj - yi
        le = ca.sqrt(ex * ex + ey * ey)
        nx, ny = ey / le, -ex / le
        b = nx * xi + ny * yi
        nu = nx * c + ny * s
        nv = -nx * s + ny * c
        out.append(nx * cx + ny * cy + ca.sqrt(rx * rx * nu * nu + ry * ry * nv * nv + eps2) - b)
    return out


_BUILDERS = {
    "paper": ellipse_edge_constraints_paper,
    "support": ellipse_edge_constraints_support,
}
