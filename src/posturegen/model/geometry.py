"""Planar geometry for non-inclusive contacts (Brossette et al., IROS 2014, sec. IV).

A contact patch is a strictly convex polygon :class:`ConvexPolygon`; the contact area of two
coplanar patches is estimated by an :class:`Ellipse` inscribed in ``P1 ∩ P2``.  Inclusion of the
ellipse in a polygon is written as one smooth constraint ``g_k <= 0`` per polygon edge, either
exactly as in the paper (eqs. 4-6, :func:`ellipse_edge_constraints_paper`) or in the
better-conditioned support-function form (:func:`ellipse_edge_constraints_support`).  Both
builders take casadi ``SX``/``MX`` (or plain float) arguments so a posture problem can reuse them.
:func:`largest_inscribed_ellipse` maximizes ``log rx + log ry`` under those constraints with IPOPT.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

import casadi as ca
import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from posturegen.errors import InputError, PosturegenError

__all__ = [
    "ConvexPolygon",
    "Ellipse",
    "ellipse_edge_constraints_paper",
    "ellipse_edge_constraints_support",
    "intersect",
    "largest_inscribed_ellipse",
]

FloatArray: TypeAlias = NDArray[np.float64]
Scalar: TypeAlias = "float | ca.SX | ca.MX"
PolygonLike: TypeAlias = "ConvexPolygon | ArrayLike"
Formulation: TypeAlias = Literal["paper", "support"]

DUP_TOL = 1e-9
"""Two vertices closer than this (absolute length) are the same point."""
AREA_TOL = 1e-12
"""A polygon with area at most this (absolute) is degenerate."""
COLLINEAR_SIN = 1e-10
"""A vertex whose turn has ``|sin| <= COLLINEAR_SIN`` is collinear with its neighbours."""
_CLEAN_SIN = 1e-8  # looser than COLLINEAR_SIN so that cleaned rings always validate
SUPPORT_EPS2 = 1e-12
"""Default smoothing ``eps2`` of the support-form constraint (squared length units)."""


def _cross2(a: FloatArray, b: FloatArray) -> FloatArray:
    """Planar cross product ``a_x b_y - a_y b_x`` along the last axis."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _signed_area(v: FloatArray) -> float:
    """Shoelace formula ``A = 1/2 sum_i p_i x p_{i+1}`` (positive for counter-clockwise)."""
    return 0.5 * float(np.sum(_cross2(v, np.roll(v, -1, axis=0))))


class ConvexPolygon:
    """Immutable strictly convex polygon, vertices stored counter-clockwise.

    Math: ``P = {x : n_i . x <= b_i, i = 0..n-1}`` with ``n_i`` the outward unit normal of edge
    ``p_i p_{i+1}`` and ``b_i = n_i . p_i``.

    Construction validates the input and raises :class:`InputError` naming ``field`` when it is
    not an ``(n, 2)`` array of finite numbers with ``n >= 3`` distinct points (tolerance
    :data:`DUP_TOL`), of area greater than :data:`AREA_TOL`, simple and strictly convex.  Either
    orientation is accepted; clockwise input is reversed.
    """

    __slots__ = ("_v", "_normals", "_offsets", "_area", "_centroid")

    _v: FloatArray
    _normals: FloatArray
    _offsets: FloatArray
    _area: float
    _centroid: FloatArray

    def __init__(self, vertices: ArrayLike, field: str = "vertices") -> None:
        v = _validate_convex(vertices, field)
        nxt = np.arange(1, len(v) + 1) % len(v)
        vn = v[nxt]
        e = vn - v
        normals = (
            np.stack([e[:, 1], -e[:, 0]], axis=1) / np.sqrt(np.einsum("ij,ij->i", e, e))[:, None]
        )
        offsets = np.einsum("ij,ij->i", normals, v)
        w = _cross2(v - v[0], vn - v[0])
        area = 0.5 * float(np.sum(w))
        c = v[0] + ((v - v[0]) + (vn - v[0])).T @ w / (6.0 * area)  # centroid, relative to p_0
        for arr in (v, normals, offsets, c):
            arr.flags.writeable = False
        object.__setattr__(self, "_v", v)
        object.__setattr__(self, "_normals", normals)
        object.__setattr__(self, "_offsets", offsets)
        object.__setattr__(self, "_area", area)
        object.__setattr__(self, "_centroid", c)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("ConvexPolygon is immutable")

    def __delattr__(self, name: str) -> None:
        raise AttributeError("ConvexPolygon is immutable")

    @property
    def vertices(self) -> FloatArray:
        """Vertices ``(n, 2)`` in counter-clockwise order (read-only array)."""
        return self._v

    @property
    def n(self) -> int:
        """Number of vertices (= number of edges)."""
        return int(self._v.shape[0])

    @property
    def area(self) -> float:
        """Area ``A = 1/2 sum_i p_i x p_{i+1}`` (> 0)."""
        return self._area

    @property
    def centroid(self) -> FloatArray:
        """Area centroid ``c = 1/(6A) sum_i (p_i + p_{i+1}) (p_i x p_{i+1})`` (read-only)."""
        return self._centroid

    def edges(self) -> list[tuple[FloatArray, FloatArray]]:
        """Edges ``(p_i, p_{i+1 mod n})`` in counter-clockwise order."""
        v = self._v
        return [(v[i], v[(i + 1) % self.n]) for i in range(self.n)]

    def halfplanes(self) -> tuple[FloatArray, FloatArray]:
        """``(normals, offsets)``: ``x in P <=> normals @ x <= offsets``, outward unit normals."""
        return self._normals, self._offsets

    def distance_inside(self, points: ArrayLike) -> FloatArray:
        """Signed margin ``min_i (b_i - n_i . x)``: > 0 inside, the distance to the border there."""
        x = np.asarray(points, dtype=float)
        if x.shape[-1:] != (2,):
            raise InputError("points", f"expected shape (..., 2), got {x.shape}", "pass 2-D points")
        return np.min(self._offsets - x @ self._normals.T, axis=-1)

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """Membership ``n_i . x <= b_i + tol`` for all edges, per point (boundary counts as in)."""
        return self.distance_inside(points) >= -tol

    def scaled(self, sx: float, sy: float | None = None) -> ConvexPolygon:
        """Image under ``(x, y) -> (sx x, sy y)`` about the origin (``sy`` defaults to ``sx``)."""
        sy = sx if sy is None else sy
        return ConvexPolygon(self._v * np.array([sx, sy], dtype=float), field="scaled")

    def transformed(self, R2: ArrayLike, t: ArrayLike = (0.0, 0.0)) -> ConvexPolygon:
        """Image under the affine map ``x -> R2 @ x + t`` (``R2`` any invertible 2x2)."""
        R = np.asarray(R2, dtype=float)
        tt = np.asarray(t, dtype=float)
        if R.shape != (2, 2) or tt.shape != (2,):
            raise InputError("R2", "expected a 2x2 matrix and a 2-vector", "pass R2 (2,2), t (2,)")
        return ConvexPolygon(self._v @ R.T + tt, field="transformed")

    def to_shapely(self) -> shapely.Polygon:
        """The same polygon as a :class:`shapely.Polygon`."""
        return shapely.Polygon(self._v)

    def __len__(self) -> int:
        return self.n

    def __repr__(self) -> str:
        pts = ", ".join(f"({x:.6g}, {y:.6g})" for x, y in self._v)
        return f"ConvexPolygon([{pts}])"


def _polygon_centroid(v: FloatArray, area: float) -> FloatArray:
    """Centroid ``1/(6A) sum (p_i + p_{i+1}) (p_i x p_{i+1})``, computed relative to ``p_0``."""
    q = v - v[0]
    qn = q[np.arange(1, len(q) + 1) % len(q)]
    w = _cross2(q, qn)
    return v[0] + np.sum((q + qn) * w[:, None], axis=0) / (6.0 * area)


def _polygon_covariance(v: FloatArray, c: FloatArray, area: float) -> FloatArray:
    """Second central moment ``1/A ∫_P (x-c)(x-c)^T dA`` of a CCW polygon."""
    q = v - c
    qn = np.roll(q, -1, axis=0)
    w = _cross2(q, qn)
    xx = np.sum(w * (q[:, 0] ** 2 + q[:, 0] * qn[:, 0] + qn[:, 0] ** 2)) / 12.0
    yy = np.sum(w * (q[:, 1] ** 2 + q[:, 1] * qn[:, 1] + qn[:, 1] ** 2)) / 12.0
    xy_terms = q[:, 0] * qn[:, 1] + 2 * q[:, 0] * q[:, 1] + 2 * qn[:, 0] * qn[:, 1]
    xy = np.sum(w * (xy_terms + qn[:, 0] * q[:, 1])) / 24.0
    return np.array([[xx, xy], [xy, yy]]) / area


def _raise_repeated(v: FloatArray, field: str) -> None:
    """InputError naming the first pair of repeated vertices, if any."""
    diff = v[:, None, :] - v[None, :, :]
    d = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    d[np.diag_indices(len(v))] = np.inf
    if np.min(d) <= DUP_TOL:
        i, j = sorted(np.unravel_index(int(np.argmin(d)), d.shape))
        raise InputError(field, f"repeated point (vertices {i} and {j})", "remove duplicates")


def _validate_convex(vertices: ArrayLike, field: str) -> FloatArray:
    """Check an ``(n, 2)`` strictly convex simple polygon; return it counter-clockwise (copy)."""
    fix_convex = "give the vertices of a convex polygon in order"
    try:
        v = np.array(vertices, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(
            field, f"not an array of numbers ({type(exc).__name__})", "give an (n, 2) array"
        ) from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise InputError(field, f"expected shape (n, 2), got {v.shape}", "give an (n, 2) array")
    n = v.shape[0]
    if n < 3:
        raise InputError(field, f"a polygon needs at least 3 vertices, got {n}", fix_convex)
    if not np.all(np.isfinite(v)):
        raise InputError(field, "vertices contain NaN or infinity", "give finite coordinates")
    nxt = np.arange(1, n + 1) % n
    e = v[nxt] - v  # e_i = p_{i+1} - p_i
    le = np.sqrt(np.einsum("ij,ij->i", e, e))
    if le.min() <= DUP_TOL:  # consecutive repeats here; other repeats fail convexity below
        _raise_repeated(v, field)
    prv = np.arange(-1, n - 1) % n
    area = 0.5 * float(np.sum(_cross2(v, v[nxt])))
    ep = e[prv]  # e_{i-1}, the edge arriving at vertex i
    turn = _cross2(ep, e) / (le[prv] * le)  # sin of the turn at vertex i
    if abs(area) <= AREA_TOL:
        if np.all(np.abs(turn) <= COLLINEAR_SIN) or shapely.LinearRing(v).is_simple:
            raise InputError(
                field, f"polygon is degenerate (area {abs(area):.3g} <= {AREA_TOL:g})", fix_convex
            )
    sign = 1.0 if area > 0 else -1.0
    st = sign * turn
    if np.all(st > COLLINEAR_SIN):
        dot = np.einsum("ij,ij->i", ep, e)
        winding = float(np.sum(np.arctan2(_cross2(ep, e), dot))) / (2 * math.pi)
        if abs(abs(winding) - 1.0) > 1e-6:
            raise InputError(
                field, f"polygon is self-intersecting (winds {abs(winding):.0f} times)", fix_convex
            )
    else:
        _raise_repeated(v, field)
        if not shapely.LinearRing(v).is_simple:
            raise InputError(field, "polygon is self-intersecting", fix_convex)
        if abs(area) <= AREA_TOL:
            raise InputError(field, f"polygon is degenerate (area {abs(area):.3g})", fix_convex)
        k = int(np.argmin(st))
        if st[k] < -COLLINEAR_SIN:
            raise InputError(field, f"polygon is not convex (reflex vertex {k})", fix_convex)
        raise InputError(
            field,
            f"collinear vertices (vertex {k} lies on the segment of its neighbours)",
            "remove vertices that lie on a straight edge",
        )
    return v if area > 0 else v[::-1].copy()


def _clean_ring(v: FloatArray) -> FloatArray:
    """Drop closing/duplicate points and vertices with turn ``|sin| <= 1e-8`` from a ring."""
    v = np.asarray(v, dtype=float)
    if len(v) > 1 and np.allclose(v[0], v[-1], rtol=0.0, atol=DUP_TOL):
        v = v[:-1]
    changed = True
    while changed and len(v) >= 3:
        changed = False
        e = np.roll(v, -1, axis=0) - v
        le = np.linalg.norm(e, axis=1)
        if np.min(le) <= 2 * DUP_TOL:
            v = np.delete(v, int(np.argmin(le)) + 1 if int(np.argmin(le)) + 1 < len(v) else 0, 0)
            changed = True
            continue
        ep = np.roll(e, 1, axis=0)
        turn = np.abs(_cross2(ep, e)) / (np.roll(le, 1) * le)
        k = int(np.argmin(turn))
        if turn[k] <= _CLEAN_SIN:
            v = np.delete(v, k, axis=0)
            changed = True
    return v


def _as_polygon(P: PolygonLike, field: str) -> ConvexPolygon:
    """Return ``P`` if already a :class:`ConvexPolygon`, else validate it as one."""
    return P if isinstance(P, ConvexPolygon) else ConvexPolygon(P, field=field)


def intersect(P1: PolygonLike, P2: PolygonLike) -> ConvexPolygon | None:
    """Convex intersection ``P1 ∩ P2`` (``None`` when empty or of area ``<= 1e-12``).

    Shapely computes the intersection; duplicate and collinear vertices of its ring are removed
    so that the result validates as a :class:`ConvexPolygon`.
    """
    A = _as_polygon(P1, "P1")
    B = _as_polygon(P2, "P2")
    g = shapely.intersection(shapely.Polygon(A.vertices), shapely.Polygon(B.vertices))
    if g.is_empty or g.geom_type != "Polygon" or g.area <= AREA_TOL:
        return None
    ring = _clean_ring(np.asarray(g.exterior.coords))
    if len(ring) < 3 or abs(_signed_area(ring)) <= AREA_TOL:
        return None
    try:
        return ConvexPolygon(ring, field="intersection")
    except InputError:  # numerically degenerate sliver
        return None


@dataclass(frozen=True)
class Ellipse:
    """Ellipse ``{c + rx cos(s) u + ry sin(s) v : s in [0, 2 pi)}``.

    Math: ``u = (cos t, sin t)``, ``v = (-sin t, cos t)`` with ``t = angle``; ``radii = (rx, ry)``.
    """

    center: FloatArray
    angle: float
    radii: tuple[float, float]

    def __post_init__(self) -> None:
        c = np.array(self.center, dtype=float)
        r = tuple(float(x) for x in np.asarray(self.radii, dtype=float).ravel())
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise InputError("center", "expected 2 finite numbers", "pass center=(x, y)")
        if len(r) != 2 or not all(math.isfinite(x) and x > 0 for x in r):
            raise InputError("radii", f"expected 2 positive radii, got {r}", "pass (rx, ry) > 0")
        if not math.isfinite(float(self.angle)):
            raise InputError("angle", "angle is not finite", "pass a finite angle in radians")
        c.flags.writeable = False
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "angle", float(self.angle))
        object.__setattr__(self, "radii", r)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Ellipse):
            return NotImplemented
        return (
            bool(np.array_equal(self.center, other.center))
            and self.angle == other.angle
            and self.radii == other.radii
        )

    def __hash__(self) -> int:
        return hash((tuple(self.center.tolist()), self.angle, self.radii))

    @property
    def area(self) -> float:
        """Area ``pi rx ry``."""
        return math.pi * self.radii[0] * self.radii[1]

    def axes(self) -> tuple[FloatArray, FloatArray]:
        """Semi-axis vectors ``(rx u, ry v)``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([c, s]) * self.radii[0], np.array([-s, c]) * self.radii[1]

    def boundary_points(self, k: int = 64) -> FloatArray:
        """``k`` points ``c + rx cos(s_j) u + ry sin(s_j) v``, ``s_j = 2 pi j / k``; (k, 2)."""
        s = 2.0 * np.pi * np.arange(int(k)) / int(k)
        a, b = self.axes()
        return self.center + np.cos(s)[:, None] * a + np.sin(s)[:, None] * b

    def inside_margin(self, P: PolygonLike) -> float:
        """Exact signed margin ``min_k (b_k - n_k.c - sqrt(rx^2 (n_k.u)^2 + ry^2 (n_k.v)^2))``.

        ``>= 0`` iff the ellipse lies in ``P``; it is the distance from the ellipse to the nearest
        edge line when positive.
        """
        normals, offsets = _as_polygon(P, "P").halfplanes()
        a, b = self.axes()
        support = np.hypot(normals @ a, normals @ b)
        return float(np.min(offsets - normals @ self.center - support))


# ---------------------------------------------------------------------------------------------
# Symbolic constraint builders
# ---------------------------------------------------------------------------------------------


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

# ---------------------------------------------------------------------------------------------
# Largest inscribed ellipse
# ---------------------------------------------------------------------------------------------

_R_MIN = 1e-6  # lower bound on rx, ry in normalized units (intersection of size ~1)
# theta is only defined modulo pi (modulo pi/2 with rx <-> ry) and it is left unbounded: when the
# normalized optimum is nearly round the theta-curvature (~ (rx - ry)^2) vanishes, IPOPT takes
# long theta steps and any finite box (tried: [-pi, pi], th0 +- 2 pi) becomes active at a
# spurious KKT point.  cos/sin make the problem periodic anyway; the returned angle is wrapped
# to (-pi/2, pi/2] with rx >= ry.
_THETA_WINDOW = math.inf
_START = (0.95, 0.9)  # initial radii as fractions of the centroid's edge margin
_SOLVER_CACHE: dict[tuple[str, int, int], ca.Function] = {}
_IPOPT_OPTS: dict[str, Any] = {
    "print_time": False,
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "ipopt.tol": 1e-10,
    "ipopt.acceptable_tol": 1e-7,
    "ipopt.constr_viol_tol": 1e-10,
    "ipopt.bound_relax_factor": 1e-10,
    "ipopt.max_iter": 300,
}


def _solver(formulation: str, n1: int, n2: int) -> ca.Function:
    """IPOPT solver (cached) for ``max log rx + log ry`` s.t. ellipse in P1 and P2 (params)."""
    key = (formulation, n1, n2)
    solver = _SOLVER_CACHE.get(key)
    if solver is not None:
        return solver
    x = ca.SX.sym("x", 5)
    p = ca.SX.sym("p", 2 * (n1 + n2))
    V1 = ca.reshape(p[: 2 * n1], 2, n1).T
    V2 = ca.reshape(p[2 * n1 :], 2, n2).T
    build = _BUILDERS[formulation]
    g = build(V1, x[0], x[1], x[2], x[3], x[4]) + build(V2, x[0], x[1], x[2], x[3], x[4])
    nlp = {"x": x, "p": p, "f": -(ca.log(x[3]) + ca.log(x[4])), "g": ca.vertcat(*g)}
    solver = ca.nlpsol(f"lie_{formulation}_{n1}_{n2}", "ipopt", nlp, _IPOPT_OPTS)
    _SOLVER_CACHE[key] = solver
    return solver


def largest_inscribed_ellipse(
    P1: PolygonLike, P2: PolygonLike, formulation: Formulation = "support"
) -> Ellipse:
    """Maximum-area ellipse in ``P1 ∩ P2``: ``max log rx + log ry`` s.t. ``g_k <= 0`` on all edges.

    The constraints are the symbolic builders of ``formulation`` ("paper" eq. 6 or "support"),
    one per edge of ``P1`` and of ``P2``, solved with IPOPT (exact Hessian).  The problem is first
    normalized by the affine map ``y = M (x - c)`` (``c`` the centroid and ``M = 1/2 S^(-1/2)``
    with ``S`` the second moment of ``P1 ∩ P2``), which maps ellipses to ellipses and preserves
    area ratios, so thin, tiny or skewed intersections become unit-size and round.  The result
    is mapped back and returned with ``rx >= ry`` and ``angle`` in ``(-pi/2, pi/2]``.

    Raises :class:`InputError` for invalid polygons or an empty intersection and
    :class:`PosturegenError` if IPOPT fails or the ellipse is not inside both polygons.
    """
    if formulation not in _BUILDERS:
        raise InputError(
            "formulation", f"unknown formulation {formulation!r}", "use 'paper' or 'support'"
        )
    A = _as_polygon(P1, "P1")
    B = _as_polygon(P2, "P2")
    ell = _warm_solve(A, B, formulation)
    return ell if ell is not None else _cold_solve(A, B, formulation)


def _cold_solve(A: ConvexPolygon, B: ConvexPolygon, formulation: Formulation) -> Ellipse:
    """IPOPT from a centred circle in the frame normalized by the intersection's moments."""
    inter = intersect(A, B)
    if inter is None:
        raise InputError(
            "P1, P2",
            "the polygons do not intersect (empty or zero-area intersection)",
            "move the patches so that they overlap",
        )
    c0 = inter.centroid
    S = _polygon_covariance(inter.vertices, c0, inter.area)
    w, U = np.linalg.eigh(S)
    M = U @ np.diag(0.5 / np.sqrt(w)) @ U.T  # y = M (x - c0)
    Minv = U @ np.diag(2.0 * np.sqrt(w)) @ U.T
    V1 = (A.vertices - c0) @ M.T
    V2 = (B.vertices - c0) @ M.T
    Vi = (inter.vertices - c0) @ M.T

    # initial guess: an ellipse strictly inside the largest centred circle, along principal axes
    ei = np.roll(Vi, -1, axis=0) - Vi
    r0 = float(np.min(np.abs(_cross2(ei, -Vi)) / np.linalg.norm(ei, axis=1)))
    cov = np.cov(Vi.T)
    _, Uv = np.linalg.eigh(cov)
    th0 = math.atan2(Uv[1, 1], Uv[0, 1])
    th0 = (th0 + math.pi / 2) % math.pi - math.pi / 2
    x0 = [0.0, 0.0, th0, _START[0] * r0, _START[1] * r0]

    # valid box: the centre lies in the intersection and no radius exceeds its diameter;
    # it keeps the paper form (whose g ~ 1/(rx ry) flattens for huge ellipses) from drifting off
    lo, hi = Vi.min(axis=0), Vi.max(axis=0)
    rmax = float(np.linalg.norm(hi - lo))
    solver = _solver(formulation, A.n, B.n)
    sol = solver(
        x0=x0,
        p=np.concatenate([V1.ravel(), V2.ravel()]),
        lbx=[lo[0], lo[1], th0 - _THETA_WINDOW, _R_MIN, _R_MIN],
        ubx=[hi[0], hi[1], th0 + _THETA_WINDOW, rmax, rmax],
        lbg=-np.inf,
        ubg=0.0,
    )
    status = solver.stats()["return_status"]
    if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        raise PosturegenError(f"largest_inscribed_ellipse: IPOPT failed ({status})")
    xs = np.asarray(sol["x"]).ravel()
    ct, st = math.cos(xs[2]), math.sin(xs[2])
    shape = Minv @ np.array([[ct * xs[3], -st * xs[4]], [st * xs[3], ct * xs[4]]])
    Us, sv, _ = np.linalg.svd(shape)
    angle = math.atan2(Us[1, 0], Us[0, 0])
    if angle <= -math.pi / 2:
        angle += math.pi
    elif angle > math.pi / 2:
        angle -= math.pi
    ell = Ellipse(center=c0 + Minv @ xs[:2], angle=angle, radii=(float(sv[0]), float(sv[1])))
    scale = math.sqrt(inter.area)
    m = min(ell.inside_margin(A), ell.inside_margin(B))
    if m < -1e-7 * scale:
        raise PosturegenError(
            f"largest_inscribed_ellipse: solution leaves the polygons (margin {m:.3g})"
        )
    return ell


# ---------------------------------------------------------------------------------------------
# Warm start: the central path of the convex form, then IPOPT certifies
# ---------------------------------------------------------------------------------------------
# The convex form of the same problem (E = {B w + d : |w| <= 1}, B symmetric positive):
#   max log det B  s.t.  |B a_k| <= b_k - a_k.d,
# whose barrier  t·(-log det B) - Σ log((b_k - a_k.d)² - |B a_k|²)  is self-concordant, so
# damped Newton steps z -= H⁻¹∇/(1 + λ) stay feasible for any polygon shape. A fixed schedule of
# _PATH_STEPS values of t (two steps each) runs as one cached CasADi function; the result, a
# point within ~ν/t of the optimum, is mapped to the frame where the ellipse is the unit circle
# and handed to IPOPT with multipliers λ_k = 1/(t·(-g_k)), so IPOPT only has to certify it.
_PATH_STEPS, _PATH_KAPPA = 24, 2.5  # t from 1 to 2.5^23 ≈ 1.4e9: IPOPT certifies in 1 iteration
_T_FINAL = _PATH_KAPPA ** (_PATH_STEPS - 1)
_PATH_CACHE: dict[int, ca.Function] = {}
_WARM_CACHE: dict[tuple[str, int, int], ca.Function] = {}
_WARM_OPTS: dict[str, Any] = {
    **_IPOPT_OPTS,
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-9,
    "ipopt.warm_start_bound_push": 1e-9,
    "ipopt.warm_start_bound_frac": 1e-9,
    "ipopt.warm_start_slack_bound_push": 1e-9,
    "ipopt.warm_start_slack_bound_frac": 1e-9,
    "ipopt.warm_start_mult_bound_push": 1e-9,
    "ipopt.max_iter": 50,
    "ipopt.tol": 1e-8,  # from the path's point (duality gap ~1e-8) IPOPT needs 1 iteration
    "error_on_fail": True,  # a failure raises (cheaper than reading the stats on success)
}


def _central_path(m: int) -> ca.Function:
    """(z0 (5,), A (m, 2), b (m,)) -> (z (5,) = (d, b11, b12, b22) near the optimum, the last
    Newton decrement λ: small when z is on the central path)."""
    f = _PATH_CACHE.get(m)
    if f is not None:
        return f
    z, A, b, t = ca.SX.sym("z", 5), ca.SX.sym("A", m, 2), ca.SX.sym("b", m), ca.SX.sym("t")
    Bm = ca.vertcat(ca.horzcat(z[2], z[3]), ca.horzcat(z[3], z[4]))
    s = b - A @ z[0:2]
    phi = -t * ca.log(z[2] * z[4] - z[3] ** 2) - ca.sum1(ca.log(s**2 - ca.sum2((A @ Bm) ** 2)))
    grad = ca.gradient(phi, z)
    dz = ca.solve(ca.hessian(phi, z)[0], grad)
    lam = ca.sqrt(ca.fmax(ca.dot(grad, dz), 0))
    step = ca.Function("step", [z, A, b, t], [z - dz / (1 + lam), lam])
    zm, Am, bm = ca.MX.sym("z", 5), ca.MX.sym("A", m, 2), ca.MX.sym("b", m)
    zz, lam_last = zm, None
    for k in range(_PATH_STEPS):
        tk = _PATH_KAPPA**k
        for _ in range(2):
            zz, lam_last = step(zz, Am, bm, tk)
    f = ca.Function(f"central_path_{m}", [zm, Am, bm], [zz, lam_last])
    _PATH_CACHE[m] = f
    return f


_PATH_Z0 = np.array([0.0, 0.0, 0.9, 0.0, 0.9])  # a circle inside the unit margin
_WARM_X0 = np.array([0.0, 0.0, 0.0, 1.0, 2.0])  # the path's ellipse in the y frame
_WARM_LBX = np.array([-4.0, -4.0, -math.inf, _R_MIN, _R_MIN])
_WARM_UBX = np.array([4.0, 4.0, math.inf, 8.0, 8.0])
_NEXT_CACHE: dict[tuple[int, int], NDArray[np.intp]] = {}


def _next_index(n1: int, n2: int) -> NDArray[np.intp]:
    """Index of each vertex's successor in the stacked vertices of two polygons."""
    key = (n1, n2)
    if key not in _NEXT_CACHE:
        _NEXT_CACHE[key] = np.concatenate(
            [np.arange(1, n1 + 1) % n1, n1 + np.arange(1, n2 + 1) % n2]
        )
    return _NEXT_CACHE[key]


def _warm_solver(formulation: str, n1: int, n2: int) -> ca.Function:
    key = (formulation, n1, n2)
    if key not in _WARM_CACHE:
        x = ca.SX.sym("x", 5)
        p = ca.SX.sym("p", 2 * (n1 + n2))
        V1 = ca.reshape(p[: 2 * n1], 2, n1).T
        V2 = ca.reshape(p[2 * n1 :], 2, n2).T
        build = _BUILDERS[formulation]
        g = build(V1, *[x[i] for i in range(5)]) + build(V2, *[x[i] for i in range(5)])
        nlp = {"x": x, "p": p, "f": -(ca.log(x[3]) + ca.log(x[4])), "g": ca.vertcat(*g)}
        _WARM_CACHE[key] = ca.nlpsol(f"lie_warm_{formulation}_{n1}_{n2}", "ipopt", nlp, _WARM_OPTS)
    return _WARM_CACHE[key]


def _interior_point(A: ConvexPolygon, B: ConvexPolygon) -> FloatArray | None:
    """A point strictly inside A ∩ B, or None: the mean of the intersection polygon's vertices
    (the vertices of each polygon inside the other and the crossings of their edges)."""
    nA, bA = A.halfplanes()
    nB, bB = B.halfplanes()
    va, vb = A.vertices, B.vertices
    pts = [va[np.all(va @ nB.T <= bB, axis=1)], vb[np.all(vb @ nA.T <= bA, axis=1)]]
    # crossings of edge i of A (p + s·r) with edge j of B (q + u·w), s, u in [0, 1]
    r = np.roll(va, -1, axis=0) - va
    w = np.roll(vb, -1, axis=0) - vb
    den = r[:, None, 0] * w[None, :, 1] - r[:, None, 1] * w[None, :, 0]  # (nA, nB)
    qp = vb[None, :, :] - va[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        s_ = (qp[..., 0] * w[None, :, 1] - qp[..., 1] * w[None, :, 0]) / den
        u_ = (qp[..., 0] * r[:, None, 1] - qp[..., 1] * r[:, None, 0]) / den
    hit = (np.abs(den) > 1e-15) & (s_ >= 0) & (s_ <= 1) & (u_ >= 0) & (u_ <= 1)
    pts.append(va[np.nonzero(hit)[0]] + s_[hit][:, None] * r[np.nonzero(hit)[0]])
    v = np.vstack(pts)
    return v.mean(axis=0) if len(v) >= 3 else None


def _quick_interior_point(A: ConvexPolygon, B: ConvexPolygon) -> FloatArray | None:
    """The first of (midpoint of the centroids, centroid of A, centroid of B) strictly inside
    both polygons with a margin of 1 % of the smaller one's size, or the general method."""
    nA, bA = A.halfplanes()
    nB, bB = B.halfplanes()
    cands = np.array([0.5 * (A.centroid + B.centroid), A.centroid, B.centroid])  # (3, 2)
    margin = np.minimum((bA - cands @ nA.T).min(axis=1), (bB - cands @ nB.T).min(axis=1))
    k = int(np.argmax(margin))
    if margin[k] > 0.01 * math.sqrt(min(A.area, B.area)):
        return cands[k]
    return _interior_point(A, B)


def _warm_solve(A: ConvexPolygon, B: ConvexPolygon, formulation: Formulation) -> Ellipse | None:
    """The fast path; None when it cannot certify (the cold path then decides)."""
    p0 = _quick_interior_point(A, B)
    if p0 is None:
        return None
    (nA, bA), (nB, bB) = A.halfplanes(), B.halfplanes()
    normals = np.vstack([nA, nB])
    offsets = np.concatenate([bA, bB]) - normals @ p0
    r0 = float(offsets.min())
    if not r0 > 1e-12 * max(1.0, float(np.abs(offsets).max())):
        return None
    z_dm, decrement = _central_path(len(offsets))(_PATH_Z0, normals, offsets / r0)
    z = np.asarray(z_dm).ravel()
    Bs = np.array([[z[2], z[3]], [z[3], z[4]]])
    det_path = float(np.linalg.det(Bs))
    # far off the central path (many edges need more Newton steps than the fixed schedule;
    # measured: λ ≈ 2-4 for 3-6 sided pairs, 5e4 for two 32-gons): the multipliers below would
    # be poor, so leave it to the cold start
    if not np.all(np.isfinite(z)) or det_path <= 0 or Bs[0, 0] <= 0 or float(decrement) > 10:
        return None
    # y = M (x' - d), x' = (x - p0)/r0, M = diag(1/σ1, 2/σ2)·Rᵀ for Bs = R diag(σ) Rᵀ: the
    # path's ellipse becomes axis-aligned with radii (1, 2), never round (θ stays well posed)
    sig, R = np.linalg.eigh(Bs)
    if np.linalg.det(R) < 0:  # a rotation, so the polygons stay counter-clockwise
        R[:, 1] = -R[:, 1]
    M = np.diag([1.0 / sig[0], 2.0 / sig[1]]) @ R.T
    Minv = R @ np.diag([sig[0], 0.5 * sig[1]])
    V = ((np.vstack([A.vertices, B.vertices]) - p0) / r0 - z[:2]) @ M.T  # both, in y
    nxt = _next_index(A.n, B.n)
    e = V[nxt] - V
    le = np.sqrt(np.einsum("ij,ij->i", e, e))
    n = np.column_stack([e[:, 1], -e[:, 0]]) / le[:, None]  # outward unit normals
    b = np.einsum("ij,ij->i", n, V)  # offsets, the centre being 0
    u = np.hypot(n[:, 0], 2.0 * n[:, 1])  # support of the (1, 2) ellipse
    if np.any(b - u <= 0):
        return None
    lam = 2.0 * b / (_T_FINAL * (b**2 - u**2))  # central-path multipliers of the rows
    if formulation == "paper":
        lam = lam * 2.0 / le  # g_paper = g_support·|e|/(rx·ry), here rx·ry = 2
    solver = _warm_solver(formulation, A.n, B.n)
    try:
        sol = solver(
            x0=_WARM_X0, p=V.ravel(), lbx=_WARM_LBX, ubx=_WARM_UBX, lbg=-np.inf, ubg=0.0, lam_g0=lam
        )
    except RuntimeError:  # error_on_fail: IPOPT did not converge from the warm start
        return None
    xs = np.asarray(sol["x"]).ravel()
    ct, st = math.cos(xs[2]), math.sin(xs[2])
    shape = r0 * Minv @ np.array([[ct * xs[3], -st * xs[4]], [st * xs[3], ct * xs[4]]])
    Us, sv, _ = np.linalg.svd(shape)
    angle = math.atan2(Us[1, 0], Us[0, 0])
    if angle <= -math.pi / 2:
        angle += math.pi
    elif angle > math.pi / 2:
        angle -= math.pi
    centre = p0 + r0 * (z[:2] + Minv @ xs[:2])
    ell = Ellipse(center=centre, angle=angle, radii=(float(sv[0]), float(sv[1])))
    if min(ell.inside_margin(A), ell.inside_margin(B)) < -1e-7 * r0:
        return None
    # the path's ellipse is feasible: a KKT point of IPOPT smaller than it is a spurious one
    # (the (c, θ, rx, ry) form is not convex), so leave it to the cold start
    if ell.area < math.pi * det_path * r0**2 * (1 - 1e-7):
        return None
    return ell
