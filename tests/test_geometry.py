"""Tests of posturegen.model.geometry: polygons, intersection, ellipse constraints, largest
ellipse."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import posturegen.model.ellipse_fit as fit
import posturegen.model.geometry as geo
from posturegen.errors import InputError, PosturegenError
from posturegen.model.ellipse_fit import largest_inscribed_ellipse
from posturegen.model.ellipse_rows import (
    ellipse_edge_constraints_paper,
    ellipse_edge_constraints_support,
)
from posturegen.model.geometry import ConvexPolygon, Ellipse, intersect
from tests.strategies import convex_polygons

COORD3 = st.floats(-3.0, 3.0, allow_nan=False)
SETTINGS = settings(
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)

# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------


def rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def random_convex(rng: np.random.Generator, kind: str | None = None) -> ConvexPolygon:
    """Convex hull of random points, or points on a random ellipse at random angles."""
    kind = kind or ("hull" if rng.random() < 0.5 else "ellipse")
    while True:
        if kind == "hull":
            pts = rng.normal(size=(int(rng.integers(3, 15)), 2)) * rng.uniform(0.3, 1.5, 2)
            hull = shapely.MultiPoint(pts).convex_hull
            if hull.geom_type != "Polygon":
                continue
            pts = np.asarray(hull.exterior.coords)[:-1]
        else:
            n = int(rng.integers(3, 10))
            t = np.sort(rng.uniform(0, 2 * np.pi, n))
            pts = np.c_[rng.uniform(0.3, 2) * np.cos(t), rng.uniform(0.3, 2) * np.sin(t)]
        pts = pts @ rot(rng.uniform(0, np.pi)).T + rng.uniform(-0.6, 0.6, 2)
        if rng.random() < 0.5:
            pts = pts[::-1]  # clockwise input must work too
        try:
            P = ConvexPolygon(pts)
        except InputError:
            continue
        if P.area > 1e-2 and np.min(np.linalg.norm(np.diff(P.vertices, axis=0), axis=1)) > 1e-4:
            return P


def intersecting_pair(seed: int) -> tuple[ConvexPolygon, ConvexPolygon, ConvexPolygon]:
    rng = np.random.default_rng(seed)
    while True:
        A, B = random_convex(rng), random_convex(rng)
        inter = intersect(A, B)
        if inter is not None and inter.area > 1e-3:
            return A, B, inter


_REF_CACHE: dict[int, ca.Function] = {}


def reference_max_ellipse_area(polys: list[ConvexPolygon]) -> float:
    """Independent convex formulation: max log det B s.t. ||B a_i|| + a_i.d <= b_i.

    Ellipse {B w + d : ||w|| <= 1}, B = [[p, q], [q, r]] symmetric positive definite.  Solved in
    coordinates translated to the intersection centroid and scaled by sqrt(area).
    """
    inter = polys[0]
    for P in polys[1:]:
        inter = intersect(inter, P)
    assert inter is not None
    c0, s = inter.centroid, math.sqrt(inter.area)
    normals = np.vstack([P.halfplanes()[0] for P in polys])
    offsets = np.concatenate([P.halfplanes()[1] for P in polys])
    offsets = (offsets - normals @ c0) / s  # half-planes in y = (x - c0) / s
    m = len(offsets)
    if m not in _REF_CACHE:
        z = ca.SX.sym("z", 5)  # p, q, r, d1, d2
        par = ca.SX.sym("par", 3 * m)
        Bm = ca.vertcat(ca.horzcat(z[0], z[1]), ca.horzcat(z[1], z[2]))
        g = []
        for i in range(m):
            a = par[2 * i : 2 * i + 2]
            Ba = Bm @ a
            g.append(ca.sqrt(ca.dot(Ba, Ba)) + ca.dot(a, z[3:5]) - par[2 * m + i])
        det = z[0] * z[2] - z[1] ** 2
        g.append(-det + 1e-10)
        nlp = {"x": z, "p": par, "f": -ca.log(det), "g": ca.vertcat(*g)}
        opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-12}
        _REF_CACHE[m] = ca.nlpsol(f"ref{m}", "ipopt", nlp, opts)
    solver = _REF_CACHE[m]
    r0 = 0.5 * float(np.min(offsets))  # centroid (origin) is inside: offsets > 0
    sol = solver(
        x0=[r0, 0.0, r0, 0.0, 0.0],
        p=np.concatenate([normals.ravel(), offsets]),
        lbx=[1e-9, -np.inf, 1e-9, -np.inf, -np.inf],
        ubx=np.inf,
        lbg=-np.inf,
        ubg=0.0,
    )
    assert solver.stats()["success"], solver.stats()["return_status"]
    z = np.asarray(sol["x"]).ravel()
    return math.pi * (z[0] * z[2] - z[1] ** 2) * s**2


def check_ellipse(ell: Ellipse, polys: list[ConvexPolygon], inter: ConvexPolygon) -> None:
    scale = math.sqrt(inter.area)
    pts = ell.boundary_points(200)
    for P in polys:
        assert np.all(P.distance_inside(pts) >= -1e-7 * scale)
        assert ell.inside_margin(P) >= -1e-7 * scale
    assert ell.area <= inter.area * (1 + 1e-9)
    assert ell.radii[0] >= ell.radii[1] > 0
    assert -math.pi / 2 < ell.angle <= math.pi / 2


# ---------------------------------------------------------------------------------------------
# ConvexPolygon
# ---------------------------------------------------------------------------------------------

SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]


@pytest.mark.parametrize(
    ("vertices", "needle"),
    [
        ([[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2]], "not convex (reflex vertex 2)"),
        ([[0, 0], [1, 1], [1, 0], [0, 1]], "self-intersecting"),  # bowtie
        ([[0, 0], [1, 0], [1, 1], [1, 1], [0, 1]], "repeated point"),
        ([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], "repeated point"),  # closed ring
        ([[0, 0], [0.5, 0], [1, 0], [1, 1], [0, 1]], "collinear"),
        ([[0, 0], [1, 1], [2, 2]], "degenerate"),
        ([[0, 0], [1, 0], [2, 1e-13]], "degenerate"),
        ([[0, 0], [1, 0], [np.nan, 1]], "NaN"),
        ([[0, 0], [1, 0], [np.inf, 1]], "NaN or infinity"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "shape"),
        ([0, 1, 2, 3], "shape"),
        ([[0, 0], [1, 0]], "at least 3"),
        ([[0, 0], [1, 0], [0, "a"]], "not an array of numbers"),
        ([[0, 0], [1, 0], [1]], "not an array of numbers"),  # ragged
        (  # pentagram: every turn is a left turn but it winds twice
            [[math.cos(4 * math.pi * k / 5), math.sin(4 * math.pi * k / 5)] for k in range(5)],
            "self-intersecting",
        ),
    ],
)
def test_invalid_polygons_raise_input_error_naming_field(vertices, needle):
    with pytest.raises(InputError) as info:
        ConvexPolygon(vertices, field="patch.left_foot")
    err = info.value
    assert err.field == "patch.left_foot"
    assert needle in err.problem
    assert err.fix
    assert "\n" not in str(err)
    assert str(err).startswith("patch.left_foot: ")


def test_orientation_is_normalized_to_ccw():
    ccw = ConvexPolygon(SQUARE)
    cw = ConvexPolygon(SQUARE[::-1])
    for P in (ccw, cw):
        assert P.area == pytest.approx(1.0)
        assert geo._signed_area(P.vertices) > 0
        assert P.n == 4 and len(P.edges()) == 4
        np.testing.assert_allclose(P.centroid, [0.5, 0.5])
    np.testing.assert_array_equal(ccw.vertices, np.asarray(SQUARE, dtype=float))
    assert {tuple(v) for v in cw.vertices} == {tuple(v) for v in ccw.vertices}


def test_polygon_is_immutable():
    P = ConvexPolygon(SQUARE)
    with pytest.raises(AttributeError):
        P.foo = 1  # type: ignore[attr-defined]
    with pytest.raises(ValueError):
        P.vertices[0, 0] = 5.0
    src = np.array(SQUARE, dtype=float)
    Q = ConvexPolygon(src)
    src[0, 0] = -10.0
    assert Q.vertices[0, 0] == 0.0
    assert "ConvexPolygon([(0, 0), (1, 0), (1, 1), (0, 1)])" == repr(Q)


def test_halfplanes_edges_and_transforms():
    P = ConvexPolygon([[0, 0], [2, 0], [2, 1], [0, 1]])
    normals, offsets = P.halfplanes()
    np.testing.assert_allclose(normals, [[0, -1], [1, 0], [0, 1], [-1, 0]], atol=1e-15)
    np.testing.assert_allclose(offsets, [0, 2, 1, 0], atol=1e-15)
    for (pi, pj), nrm, b in zip(P.edges(), normals, offsets, strict=True):
        assert nrm @ pi == pytest.approx(b) and nrm @ pj == pytest.approx(b)
    assert P.distance_inside([1.0, 0.5]) == pytest.approx(0.5)
    assert P.distance_inside([3.0, 0.5]) == pytest.approx(-1.0)
    assert list(P.contains([[1, 0.5], [2, 1], [2.1, 0.5]])) == [True, True, False]
    assert P.scaled(2, 3).area == pytest.approx(12.0)
    assert P.scaled(-1, 1).area == pytest.approx(2.0)  # mirror: re-oriented to CCW
    T = P.transformed(rot(0.3), [1, 2])
    assert T.area == pytest.approx(2.0)
    np.testing.assert_allclose(T.centroid, rot(0.3) @ [1, 0.5] + [1, 2])
    assert P.to_shapely().area == pytest.approx(2.0)
    with pytest.raises(InputError):
        P.scaled(0, 1)


@settings(SETTINGS, max_examples=30)
@given(P=convex_polygons(), pts=st.lists(st.tuples(COORD3, COORD3), min_size=1, max_size=200))
def test_contains_and_distance_match_shapely(P, pts):
    pts = np.array(pts)
    sp = P.to_shapely()
    dist = P.distance_inside(pts)
    for x, d in zip(pts, dist, strict=True):
        p = shapely.Point(x)
        if abs(d) > 1e-9:
            assert (d > 0) == sp.contains(p)
        if d > 0:  # inside: margin is the distance to the boundary
            assert d == pytest.approx(sp.exterior.distance(p), abs=1e-12)
    assert np.array_equal(P.contains(pts), dist >= -1e-9)


# ---------------------------------------------------------------------------------------------
# intersect
# ---------------------------------------------------------------------------------------------


@settings(SETTINGS, max_examples=100)
@given(A=convex_polygons(), B=convex_polygons())
def test_intersect_area_matches_shapely(A, B):
    expected = A.to_shapely().intersection(B.to_shapely()).area
    inter = intersect(A, B)
    if inter is None:
        assert expected <= 1e-12
    else:
        assert isinstance(inter, ConvexPolygon)
        assert inter.area == pytest.approx(expected, rel=1e-9, abs=1e-14)
        assert np.all(A.contains(inter.vertices, tol=1e-9))
        assert np.all(B.contains(inter.vertices, tol=1e-9))


def test_intersect_disjoint_touching_and_cleaning():
    A = ConvexPolygon(SQUARE)
    assert intersect(A, A.transformed(np.eye(2), [3, 0])) is None
    assert intersect(A, A.transformed(np.eye(2), [1, 0])) is None  # shares an edge only
    assert intersect(A, A.transformed(np.eye(2), [1, 1])) is None  # shares a vertex only
    same = intersect(A, np.asarray(SQUARE)[::-1])  # identical: no duplicate/collinear left
    assert same is not None and same.n == 4 and same.area == pytest.approx(1.0)
    half = intersect(A, A.transformed(np.eye(2), [0.5, 0]))
    assert half is not None and half.n == 4 and half.area == pytest.approx(0.5)


# ---------------------------------------------------------------------------------------------
# Ellipse and constraint builders
# ---------------------------------------------------------------------------------------------


def test_ellipse_basics():
    e = Ellipse(center=np.array([1.0, 2.0]), angle=math.pi / 2, radii=(2.0, 1.0))
    assert e.area == pytest.approx(2 * math.pi)
    a, b = e.axes()
    np.testing.assert_allclose(a, [0, 2], atol=1e-15)
    np.testing.assert_allclose(b, [-1, 0], atol=1e-15)
    pts = e.boundary_points(8)
    assert pts.shape == (8, 2)
    np.testing.assert_allclose(pts[0], [1, 4], atol=1e-15)
    rect = ConvexPolygon([[0, -1], [2, -1], [2, 5], [0, 5]])  # tight in x, 1 of room in y
    assert e.inside_margin(rect) == pytest.approx(0.0, abs=1e-15)
    assert e == Ellipse(center=(1.0, 2.0), angle=math.pi / 2, radii=(2.0, 1.0))
    assert len({e, Ellipse(center=(1.0, 2.0), angle=math.pi / 2, radii=(2.0, 1.0))}) == 1
    for bad in [dict(radii=(1.0, -1.0)), dict(center=(np.nan, 0.0)), dict(angle=np.inf)]:
        kw = dict(center=(0.0, 0.0), angle=0.0, radii=(1.0, 1.0)) | bad
        with pytest.raises(InputError):
            Ellipse(**kw)


@settings(SETTINGS, max_examples=30)
@given(
    P=convex_polygons(),
    offset=st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4)),
    angle=st.floats(-4.0, 4.0),
    radii=st.tuples(st.floats(0.01, 1.0), st.floats(0.01, 1.0)),
)
def test_inside_margin_is_exact_support_margin(P, offset, angle, radii):
    e = Ellipse(P.centroid + np.array(offset), angle, radii)
    pts = e.boundary_points(20000)
    sampled = float(np.min(P.halfplanes()[1][None, :] - pts @ P.halfplanes()[0].T))
    # the exact margin is the min over the continuum of the ellipse: <= every sample, and close
    assert e.inside_margin(P) <= sampled + 1e-12
    assert e.inside_margin(P) == pytest.approx(sampled, abs=1e-6)


def test_circle_well_inside_gives_negative_g_and_outside_positive():
    P = ConvexPolygon(np.asarray(SQUARE)[::-1] * 2.0)  # CW input, normalized to CCW
    for build in (ellipse_edge_constraints_paper, ellipse_edge_constraints_support):
        g_in = build(P, 1.0, 1.0, 0.3, 0.5, 0.5)
        assert len(g_in) == 4 and all(float(g) < 0 for g in g_in)
        g_out = build(P, 1.0, 1.0, 0.0, 1.5, 0.2)  # sticks out on the left and the right
        assert sum(float(g) > 0 for g in g_out) == 2


@settings(SETTINGS, max_examples=30)
@given(seed=st.integers(0, 2**31 - 1))
def test_paper_and_support_forms_describe_the_same_set(seed):
    rng = np.random.default_rng(seed)
    P = random_convex(rng)
    x = ca.SX.sym("x", 5)
    g_paper = ca.Function(
        "gp", [x], [ca.vertcat(*ellipse_edge_constraints_paper(P, *ca.vertsplit(x)))]
    )
    g_supp = ca.Function(
        "gs", [x], [ca.vertcat(*ellipse_edge_constraints_support(P.vertices, *ca.vertsplit(x)))]
    )
    edge_len = np.linalg.norm(np.roll(P.vertices, -1, axis=0) - P.vertices, axis=1)
    agree = 0
    for _ in range(100):
        c = P.centroid + rng.normal(0, 0.5, 2)
        th, rx, ry = rng.uniform(-4, 4), *rng.uniform(0.01, 1.2, 2)
        z = [c[0], c[1], th, rx, ry]
        gp = np.asarray(g_paper(z)).ravel()
        gs = np.asarray(g_supp(z)).ravel()
        # numeric (float) evaluation gives the same expressions
        assert np.allclose(gp, ellipse_edge_constraints_paper(P, *z), atol=1e-12)
        # exact relation g_paper = g_support * |p_i p_j| / (rx ry) (up to eps2)
        np.testing.assert_allclose(gp, gs * edge_len / (rx * ry), rtol=1e-6, atol=1e-5)
        margin = Ellipse(c, th, (rx, ry)).inside_margin(P)
        if abs(margin) > 1e-5:
            inside = margin > 0
            assert (gp.max() < 0) == inside
            assert (gs.max() < 0) == inside
            agree += 1
    assert agree > 50


def test_builders_accept_symbolic_polygon_and_mx():
    V = ca.MX.sym("V", 4, 2)
    x = ca.MX.sym("x", 5)
    for build in (ellipse_edge_constraints_paper, ellipse_edge_constraints_support):
        f = ca.Function("f", [V, x], [ca.vertcat(*build(V, *ca.vertsplit(x)))])
        num = build(ConvexPolygon(SQUARE), 0.5, 0.5, 0.2, 0.3, 0.2)
        sym = np.asarray(f(np.asarray(SQUARE, float), [0.5, 0.5, 0.2, 0.3, 0.2])).ravel()
        np.testing.assert_allclose(sym, np.asarray(num, dtype=float), atol=1e-14)


def test_support_eps2_is_conservative():
    P = ConvexPolygon(SQUARE)
    g0 = ellipse_edge_constraints_support(P, 0.5, 0.5, 0.0, 0.5, 0.5, eps2=0.0)
    g1 = ellipse_edge_constraints_support(P, 0.5, 0.5, 0.0, 0.5, 0.5, eps2=1e-6)
    assert all(float(a) == pytest.approx(0.0, abs=1e-15) for a in g0)  # tangent circle
    assert all(0 < float(b) <= 1e-3 for b in g1)  # shrinks by at most sqrt(eps2)


# ---------------------------------------------------------------------------------------------
# largest_inscribed_ellipse
# ---------------------------------------------------------------------------------------------


@settings(SETTINGS, max_examples=60)
@given(seed=st.integers(0, 2**31 - 1))
def test_largest_ellipse_random_pairs_match_independent_formulation(seed):
    A, B, inter = intersecting_pair(seed)
    ref = reference_max_ellipse_area([A, B])
    assert ref <= inter.area
    for formulation in ("support", "paper"):
        ell = largest_inscribed_ellipse(A, B, formulation=formulation)
        check_ellipse(ell, [A, B], inter)
        assert ell.area == pytest.approx(ref, rel=1e-4)
    # plain arrays in either orientation give the same answer
    ell2 = largest_inscribed_ellipse(A.vertices[::-1], np.asarray(B.vertices))
    assert ell2.area == pytest.approx(ref, rel=1e-4)


@pytest.mark.parametrize("formulation", ["support", "paper"])
@pytest.mark.parametrize(("w", "h", "angle"), [(2.0, 1.0, 0.0), (3.0, 0.5, 0.7), (1.0, 1.0, 0.2)])
def test_rectangle_known_optimum(formulation, w, h, angle):
    rect = np.array([[0, 0], [w, 0], [w, h], [0, h]]) @ rot(angle).T + [0.3, -0.2]
    big = np.array([[-10, -10], [10, -10], [10, 10], [-10, 10]])
    ell = largest_inscribed_ellipse(rect, big, formulation=formulation)
    np.testing.assert_allclose(ell.radii, sorted([w / 2, h / 2], reverse=True), rtol=1e-6)
    np.testing.assert_allclose(ell.center, rect.mean(axis=0), atol=1e-6)
    if w != h:  # the major axis is along the long side (angle mod pi)
        d = (ell.angle - angle) % math.pi
        assert min(d, math.pi - d) < 1e-5


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_triangle_is_steiner_inellipse(formulation):
    tri = np.array([[0.0, 0.0], [4.0, 0.5], [1.0, 3.0]])
    ell = largest_inscribed_ellipse(tri, tri, formulation=formulation)
    T = ConvexPolygon(tri)
    assert ell.area == pytest.approx(math.pi / (3 * math.sqrt(3)) * T.area, rel=1e-6)
    np.testing.assert_allclose(ell.center, tri.mean(axis=0), atol=1e-6)  # centred at centroid
    # the Steiner inellipse touches each side at its midpoint: midpoints lie on the ellipse
    u, v = ell.axes()
    Q = np.linalg.inv(np.c_[u, v])
    for p, q in T.edges():
        assert np.linalg.norm(Q @ ((p + q) / 2 - ell.center)) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_skewed_parallelogram(formulation):
    para = np.array([[0.0, 0.0], [1.0, 0.0], [1.0 + 3.0, 0.2], [3.0, 0.2]])
    ell = largest_inscribed_ellipse(para, para * 1.0, formulation=formulation)
    assert ell.area == pytest.approx(math.pi / 4 * ConvexPolygon(para).area, rel=1e-6)


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_thin_1_to_50(formulation):
    thin = np.array([[0, 0], [1.0, 0], [1.0, 0.02], [0, 0.02]]) @ rot(0.4).T + [2.0, 1.0]
    other = ConvexPolygon([[1.0, 0.0], [3.5, 0.5], [2.8, 2.5], [1.2, 2.0]])
    inter = intersect(thin, other)
    assert inter is not None
    ell = largest_inscribed_ellipse(thin, other, formulation=formulation)
    check_ellipse(ell, [ConvexPolygon(thin), other], inter)
    assert ell.radii[1] == pytest.approx(0.01, rel=1e-5)  # fills the width
    assert ell.area == pytest.approx(
        reference_max_ellipse_area([ConvexPolygon(thin), other]), rel=1e-4
    )


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_tiny_1mm(formulation):
    tri = np.array([[0.0, 0.0], [1e-3, 0.0], [0.3e-3, 0.9e-3]]) + [5.0, -3.0]
    sq = np.array([[0.0, 0.0], [1e-3, 0.0], [1e-3, 1e-3], [0.0, 1e-3]]) + [5.0002, -3.0001]
    A, B = ConvexPolygon(tri), ConvexPolygon(sq)
    inter = intersect(A, B)
    assert inter is not None and inter.area < 1e-6
    ell = largest_inscribed_ellipse(A, B, formulation=formulation)
    check_ellipse(ell, [A, B], inter)
    assert ell.area == pytest.approx(reference_max_ellipse_area([A, B]), rel=1e-4)
    solo = largest_inscribed_ellipse(tri, tri, formulation=formulation)
    assert solo.area == pytest.approx(math.pi / (3 * math.sqrt(3)) * A.area, rel=1e-6)


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_32_sided(formulation):
    t = 2 * np.pi * np.arange(32) / 32
    A = ConvexPolygon(np.c_[np.cos(t), 0.6 * np.sin(t)])
    B = ConvexPolygon((np.c_[0.8 * np.cos(t), np.sin(t)] @ rot(0.5).T) + [0.3, 0.1])
    inter = intersect(A, B)
    assert inter is not None and inter.n >= 20
    ell = largest_inscribed_ellipse(A, B, formulation=formulation)
    check_ellipse(ell, [A, B], inter)
    assert ell.area == pytest.approx(reference_max_ellipse_area([A, B]), rel=1e-4)


def test_empty_intersection_and_bad_arguments_raise_input_error():
    sq = np.asarray(SQUARE, dtype=float)
    with pytest.raises(InputError) as info:
        largest_inscribed_ellipse(sq, sq + [2.0, 0.0])
    assert "do not intersect" in info.value.problem
    with pytest.raises(InputError) as info:
        largest_inscribed_ellipse(sq, [[0, 0], [1, 1], [1, 0], [0, 1]])
    assert info.value.field == "P2"
    with pytest.raises(InputError) as info:
        largest_inscribed_ellipse(sq, sq, formulation="nope")  # type: ignore[arg-type]
    assert info.value.field == "formulation"


def test_ipopt_failure_raises_posturegen_error(monkeypatch):
    monkeypatch.setattr(fit, "_SOLVER_CACHE", {})
    monkeypatch.setattr(fit, "_WARM_CACHE", {})
    monkeypatch.setitem(fit._IPOPT_OPTS, "ipopt.max_iter", 1)
    monkeypatch.setitem(fit._WARM_OPTS, "ipopt.max_iter", 0)
    with pytest.raises(PosturegenError) as info:
        largest_inscribed_ellipse(SQUARE, np.asarray(SQUARE) + 0.5)
    assert type(info.value) is PosturegenError
    assert "IPOPT failed" in str(info.value)


def test_solver_is_cached_per_formulation_and_sizes():
    A = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=float)
    B = np.array([[1, -1], [3, 0], [3, 3], [1, 3], [0, 1]], dtype=float)
    largest_inscribed_ellipse(A, B)
    solver = fit._WARM_CACHE[("support", 4, 5)]
    path = fit._PATH_CACHE[9]
    largest_inscribed_ellipse(A + 0.1, B)
    assert fit._WARM_CACHE[("support", 4, 5)] is solver
    assert fit._PATH_CACHE[9] is path


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_warm_start_is_used_and_agrees_with_the_cold_start(formulation):
    """Small polygons go through the central-path warm start (IPOPT then certifies in one
    iteration); its ellipse is the cold start's to 1e-6."""
    used = 0
    for seed in range(25):
        P, Q, _ = intersecting_pair(1000 + seed)
        warm = fit._warm_solve(P, Q, formulation)
        cold = fit._cold_solve(P, Q, formulation)
        if warm is not None:
            used += 1
            assert warm.area == pytest.approx(cold.area, rel=1e-6)
            np.testing.assert_allclose(warm.center, cold.center, atol=1e-4 * math.sqrt(cold.area))
    assert used >= 12


def test_many_sided_pairs_fall_back_to_the_cold_start():
    t = np.linspace(0, 2 * np.pi, 33)[:-1]
    P = geo.ConvexPolygon(np.c_[np.cos(t), np.sin(t)])
    Q = geo.ConvexPolygon(np.c_[0.5 + np.cos(t + 0.1), 0.2 + np.sin(t + 0.1)])
    assert fit._warm_solve(P, Q, "support") is None  # the fixed path is too short for 64 rows
    assert largest_inscribed_ellipse(P, Q).area == pytest.approx(
        fit._cold_solve(P, Q, "support").area, rel=1e-9
    )
