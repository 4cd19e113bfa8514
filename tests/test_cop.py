"""Contacts a robot can use by default: the default minimum contact ellipse (a fraction of the
smaller inradius of the robot patch and the surface) and the centre-of-pressure margin
(rows owned by fixed and support contacts, re-checked by verify)."""

from __future__ import annotations

import copy
from unittest import mock

import numpy as np
import pinocchio as pin
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from posturegen import problem_from_dict, solve
from posturegen.climb.stance import next_problem
from posturegen.errors import InputError
from posturegen.model.geometry import ConvexPolygon, intersect
from posturegen.model.min_ellipse import MIN_RADIUS_FRACTION, default_min_radii, inscribed_disc
from posturegen.terms.contacts import patch_in_surface, polygon_in_surface
from posturegen.terms.cop import DEFAULT_COP_MARGIN
from posturegen.verify import cop_shortfall, ellipse_depth, verify_posture
from tests.test_contacts import step_problem

GROUND = {"name": "ground", "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]}
TALOS_HAND_INRADIUS = 0.0296  # [m] the trapezoid of talos.yaml


@st.composite
def convex_polygons(draw: st.DrawFn) -> ConvexPolygon:
    """The convex hull of 3-12 points drawn in a 0.4 m square, at least 1 cm² in area; no
    subnormal coordinate (1e-308 m: GEOS, the shapely oracle of the tests below, raised
    'non-noded intersection' on one, 2026-12-05, where posturegen's own intersection held)."""
    coord = st.floats(-0.2, 0.2, allow_subnormal=False)
    pts = draw(st.lists(st.tuples(coord, coord), min_size=3, max_size=12))
    hull = shapely.MultiPoint(pts).convex_hull
    assume(isinstance(hull, shapely.Polygon) and hull.area >= 1e-4)
    try:  # the hull keeps near-collinear and near-repeated points, which are rejected
        return ConvexPolygon(np.array(hull.exterior.coords)[:-1])
    except InputError:
        assume(False)
        raise


@settings(max_examples=60, deadline=None)
@given(P=convex_polygons())
def test_inscribed_disc_is_the_largest(P):
    centre, radius = inscribed_disc(P)
    assert P.distance_inside(centre[None])[0] >= radius - 1e-12  # the disc is inside
    reference = shapely.maximum_inscribed_circle(P.to_shapely(), 1e-7).length
    assert radius >= reference - 1e-6  # and none larger is (shapely's, to its tolerance)


def test_default_min_radii_are_the_fraction_of_the_smaller_inradius(talos):
    hand = talos.patch("right_hand").polygon
    assert inscribed_disc(hand)[1] == pytest.approx(TALOS_HAND_INRADIUS, abs=1e-4)
    table = ConvexPolygon([[-0.3, -0.5], [0.3, -0.5], [0.3, 0.5], [-0.3, 0.5]])
    rung = ConvexPolygon([[-0.0125, -0.4], [0.0125, -0.4], [0.0125, 0.4], [-0.0125, 0.4]])
    r_hand = MIN_RADIUS_FRACTION * inscribed_disc(hand)[1]
    assert default_min_radii(hand, table) == pytest.approx((r_hand, r_hand))
    assert default_min_radii(hand, rung) == pytest.approx((MIN_RADIUS_FRACTION * 0.0125,) * 2)
    problem = problem_from_dict(step_problem({"type": "support"}))
    foot = problem.contacts[1]
    r_foot = MIN_RADIUS_FRACTION * min(0.057, 0.06)  # the sole's half width, the step's half
    assert foot.ellipse.min_radii == pytest.approx((r_foot, r_foot))


def table_problem(**options) -> dict:
    """TALOS standing, a 0.4 × 0.8 m table at 0.8 m with its front edge 0.45 m ahead, both
    hands on it as support contacts (defaults), the torso pushed forward so that they bear
    load."""
    return {
        "robot": "talos",
        "surfaces": [
            GROUND,
            {
                "name": "table",
                "position": [0.65, 0.0, 0.8],
                "vertices": [[-0.2, -0.4], [0.2, -0.4], [0.2, 0.4], [-0.2, 0.4]],
            },
        ],
        "contacts": [
            {
                "robot_patch": "left_sole",
                "surface": "ground",
                "type": "fixed",
                "position": [0, 0.1],
            },
            {
                "robot_patch": "right_sole",
                "surface": "ground",
                "type": "fixed",
                "position": [0, -0.1],
            },
            {"robot_patch": "left_hand", "surface": "table", "type": "support"},
            {"robot_patch": "right_hand", "surface": "table", "type": "support"},
        ],
        "tasks": [{"type": "position", "frame": "torso_2_link", "target": [0.25, 0.0, 1.05]}],
        "options": options,
    }


def _cop_and_depths(problem, result, name):
    """CoP of a contact (surface plane), its depth in the ellipse and in the surface polygon,
    and the fraction of the robot patch on the surface, computed here from the posture."""
    c = next(x for x in result.posture["contacts"] if x["name"] == name)
    contact = next(x for x in problem.contacts if x.name == name)
    T_ws = contact.surface.T_world_surface
    pts = np.array([f["point"] for f in c["forces"]])
    local = (pts - T_ws.translation) @ T_ws.rotation
    fn = np.array([f["force"] for f in c["forces"]]) @ T_ws.rotation[:, 2]
    cop = fn @ local[:, :2] / fn.sum()
    ell = c["ellipse"]
    centre = np.array(ell["center_in_surface"])
    axes = tuple((T_ws.rotation.T @ np.array(a))[:2] for a in ell["axes"])
    pos, yaw = contact.realized_pose(problem.robot.model, result.q)
    patch = polygon_in_surface(contact.patch, patch_in_surface(pos, yaw))
    on = intersect(patch, contact.surface.polygon)
    overlap = 0.0 if on is None else on.area / patch.area
    return (
        fn.sum(),
        ellipse_depth(cop, centre, axes),
        contact.surface.polygon.distance_inside(cop[None])[0],
        overlap,
    )


def test_hands_on_a_table_lie_flat_with_the_defaults(talos):
    """Before: each hand touched a table corner with a 0.5 × 0.5 cm ellipse bearing ~100 N.
    With the defaults each hand's contact disc is 3/4 of its inradius, its CoP 5 mm inside
    it, and most of the hand is on the table."""
    problem = problem_from_dict(table_problem())
    r = solve(problem)
    assert r.success, r.message
    r_min = MIN_RADIUS_FRACTION * inscribed_disc(talos.patch("left_hand").polygon)[1]
    for name in ("left_hand", "right_hand"):
        c = next(x for x in r.posture["contacts"] if x["name"] == name)
        assert min(c["ellipse"]["radii"]) >= r_min - 1e-6
        load, depth_ellipse, depth_table, overlap = _cop_and_depths(problem, r, name)
        assert load > 0.1 * talos.weight  # the hands bear load
        assert depth_ellipse >= DEFAULT_COP_MARGIN - 1e-6
        assert depth_table >= 0.9 * r_min  # the CoP well inside the table, not on its corner
        assert overlap > 0.5  # most of the hand is on the table
    assert r.posture["checks"]["centre of pressure margin"]["ok"]


@pytest.mark.parametrize("margin", [None, 0.0, 0.02])
def test_the_foot_left_on_a_step_edge_keeps_its_cop_inside(margin):
    """README-style stance: the right foot found on a 12 cm step (support, defaults), then
    fixed, the left foot released, so the CoP must go towards the ground foot's side. Before:
    an intersection of 10.5 cm² and all 886 N on one vertex of the toe. Now the intersection
    holds a disc of 3/4 of the sole's inradius and the CoP keeps the margin (default 5 mm);
    with cop_margin 0 it goes to the edge: the margin is what keeps it inside."""
    data = step_problem({"type": "support"})
    if margin is not None:
        data["options"] = {"cop_margin": margin}
    problem = problem_from_dict(data)
    r = solve(problem)
    assert r.success, r.message
    nxt = next_problem(problem, r, fix="right_sole", release="left_sole")
    fixed = nxt.contacts[0]
    wanted = DEFAULT_COP_MARGIN if margin is None else margin
    assert fixed.cop_margin == wanted
    assert inscribed_disc(fixed.area)[1] >= MIN_RADIUS_FRACTION * 0.057 - 1e-6
    r2 = solve(nxt)
    assert r2.success, r2.message
    c = r2.posture["contacts"][0]
    fn = np.array([f["force"] for f in c["forces"]]) @ fixed.surface.T_world_surface.rotation[:, 2]
    cop = fn @ fixed.area.vertices / fn.sum()  # the force points are the area's vertices
    depth = fixed.area.distance_inside(cop[None])[0]
    assert depth >= wanted - 1e-6
    if wanted == 0:
        assert depth < 1e-3  # free, the CoP goes to the edge
    else:
        assert depth < wanted + 1e-3  # the margin binds


def test_verify_rejects_a_cop_moved_to_an_edge(talos):
    problem = problem_from_dict(table_problem())
    r = solve(problem)
    assert r.success, r.message
    for kind, index in (("support", 2), ("fixed", 0)):
        bad = copy.deepcopy(r.posture)
        forces = bad["contacts"][index]["forces"]
        total = np.sum([f["force"] for f in forces], axis=0)
        for f in forces:  # the whole load on the first force point, at the region's edge
            f["force"] = (total if f is forces[0] else 0 * total).tolist()
        failed = {c.name for c in verify_posture(bad, talos.model).failures}
        assert "centre of pressure margin" in failed, kind
    raised = copy.deepcopy(r.posture)
    raised["contacts"][2]["cop_margin"] = 0.2  # more than the ellipse can hold
    assert "centre of pressure margin" in {
        c.name for c in verify_posture(raised, talos.model).failures
    }


@settings(max_examples=40, deadline=None)
@given(
    radii=st.tuples(st.floats(0.005, 0.3), st.floats(0.005, 0.3)),
    angle=st.floats(0, np.pi),
    where=st.tuples(st.floats(0, 2 * np.pi), st.floats(0, 0.95) | st.floats(1.05, 2.0)),
)
def test_ellipse_depth_is_a_tight_lower_bound(radii, angle, where):
    """Inside: against the distance to 200,000 boundary points (above the true one by less
    than 3e-8 m this far inside); outside: negative."""
    a1 = radii[0] * np.array([np.cos(angle), np.sin(angle)])
    a2 = radii[1] * np.array([-np.sin(angle), np.cos(angle)])
    centre = np.array([0.3, -0.2])
    point = centre + where[1] * (np.cos(where[0]) * a1 + np.sin(where[0]) * a2)
    depth = ellipse_depth(point, centre, (a1, a2))
    if where[1] > 1:
        assert depth < 0
        return
    t = np.linspace(0, 2 * np.pi, 200_000, endpoint=False)
    boundary = centre + np.outer(np.cos(t), a1) + np.outer(np.sin(t), a2)
    sampled = np.linalg.norm(boundary - point, axis=1).min()
    assert sampled - 2e-7 <= depth <= sampled + 1e-12


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"options": {"cop_margin": -0.01}}, "options.cop_margin"),
        ({"contact": {"cop_margin": "1 cm"}}, "contacts[1].cop_margin"),
        ({"contact": {"type": "inclusive", "cop_margin": 0.01}}, "contacts[1].cop_margin"),
        ({"step": 0.008}, "contacts[1].cop_margin"),
    ],
)
def test_cop_margin_is_validated(change, field):
    """A fixed foot on a step 8 mm deep: no point of it is 5 mm inside (bears no force)."""
    contact = {"type": "fixed", "position": [0.0, 0.0], **change.get("contact", {})}
    if contact["type"] != "fixed":
        del contact["position"]
    data = step_problem(contact, depth=change.get("step", 0.12))
    data["options"] = change.get("options", {})
    with pytest.raises(InputError) as info:
        problem_from_dict(data)
    assert str(info.value).startswith(field)


@settings(max_examples=80, deadline=None)
@given(
    P=convex_polygons(),
    Q=convex_polygons(),
    shift=st.tuples(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)),
    point=st.tuples(st.floats(-0.4, 0.4), st.floats(-0.4, 0.4)),
    margin=st.floats(0.001, 0.05),
)
def test_fixed_contact_cop_depth_is_the_intersections(P, Q, shift, point, margin):
    """A fixed contact's CoP shortfall (no ellipse: the region is both polygons' intersection
    at the realized pose) equals margin minus the depth in the intersection that shapely
    computes, inside or outside, and inf when they do not meet; the patch frame is flipped
    (normals opposite), so its polygon reaches the surface plane clockwise."""
    T_ws = pin.SE3.Identity()
    T_wc = pin.SE3(pin.utils.rpyToMatrix(np.pi, 0.0, 0.0), np.array([*shift, 0.0]))
    patch_s = np.column_stack([Q.vertices, np.zeros(Q.n)]) @ T_wc.rotation.T + T_wc.translation
    contact = {"cop_margin": margin, "forces": [{"point": [*point, 0.0], "force": [0, 0, 2.0]}]}
    got = cop_shortfall(contact, T_ws, P, T_wc, Q, weight=1.0)
    region = intersect(ConvexPolygon(patch_s[:, :2]), P)
    if region is None:
        assert got == np.inf
        return
    depth = float(region.distance_inside(np.array([point]))[0])
    assert got == pytest.approx(margin - depth, abs=1e-9)
    if depth > 1e-5:  # well inside: read off both polygons, the intersection never built
        with mock.patch("posturegen.verify.intersect", side_effect=AssertionError("built")):
            assert cop_shortfall(contact, T_ws, P, T_wc, Q, weight=1.0) == got
    shapely_region = shapely.intersection(P.to_shapely(), shapely.Polygon(patch_s[:, :2]))
    if shapely_region.contains(shapely.Point(point)):
        inside = shapely_region.exterior.distance(shapely.Point(point))
        assert got == pytest.approx(margin - inside, abs=1e-9)


def test_the_moment_of_a_contacts_forces_is_the_sum_of_their_cross_products():
    """verify's Σ r_i × f_i (from rᵀf) equals numpy's cross products, one to eight points."""
    from posturegen.verify import _moment

    rng = np.random.default_rng(20261206)
    for k in range(1, 9):
        r = rng.normal(size=(k, 3))
        f = 100.0 * rng.normal(size=(k, 3))
        np.testing.assert_allclose(_moment(r, f), np.cross(r, f).sum(axis=0), rtol=0, atol=1e-11)
