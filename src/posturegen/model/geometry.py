"""Planar geometry for non-inclusive contacts (Brossette et al., IROS 2014, sec. IV).

A contact patch is a strictly convex polygon :class:`ConvexPolygon`; the contact area of two
coplanar patches is estimated by an :class:`Ellipse` inscribed in ``P1 ∩ P2`` (:func:`intersect`).
The per-edge inclusion rows of an ellipse are in :mod:`posturegen.model.ellipse_rows`, the
largest inscribed ellipse in :mod:`posturegen.model.ellipse_fit`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, TypeAlias

import casadi as ca
import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError

__all__ = ["ConvexPolygon", "Ellipse", "intersect"]

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
