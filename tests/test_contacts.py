"""Non-inclusive contacts in postures: geometric (paper and support forms), support, inclusive
and point contacts, area maximization, thin patches and the next stance."""

from __future__ import annotations

import copy
import dataclasses

import casadi as ca
import numpy as np
import pytest

from posturegen import problem_from_dict, solve
from posturegen.climb.stance import next_problem
from posturegen.errors import InputError
from posturegen.model.ellipse_fit import largest_inscribed_ellipse
from posturegen.model.geometry import Ellipse, intersect
from posturegen.terms.contacts import patch_in_surface, polygon_in_surface
from posturegen.terms.cop import DEFAULT_COP_MARGIN
from posturegen.terms.friction import FrictionModel
from posturegen.verify import verify_posture


def step_problem(
    contact: dict,
    depth: float = 0.12,
    width: float = 0.6,
    height: float = 0.1,
    x: float = 0.3,
    tasks: list | None = None,
) -> dict:
    """Talos, left foot fixed on the ground, right foot on a step as ``contact``."""
    return {
        "robot": "talos",
        "surfaces": [
            {"name": "ground", "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]},
            {
                "name": "step",
                "position": [x, -0.1, height],
                "rpy": [0, 0, 0.1],
                "vertices": [
                    [-depth / 2, -width / 2],
                    [depth / 2, -width / 2],
                    [depth / 2, width / 2],
                    [-depth / 2, width / 2],
                ],
            },
        ],
        "contacts": [
            {
                "robot_patch": "left_sole",
                "surface": "ground",
                "type": "fixed",
                "position": [0.0, 0.1],
            },
            {"robot_patch": "right_sole", "surface": "step", **contact},
        ],
        "tasks": tasks or [],
    }


def _final_intersection(problem, result):
    c = problem.contacts[1]
    pos, yaw = c.realized_pose(problem.robot.model, result.q)
    return polygon_in_surface(c.patch, patch_in_surface(pos, yaw)), c.surface.polygon


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_geometric_contact_on_a_step_shorter_than_the_foot(formulation):
    problem = problem_from_dict(
        step_problem({"type": "geometric", "formulation": formulation, "min_radii": [0.05, 0.04]})
    )
    counts = problem.constraint_counts()
    assert counts["contact.right_sole.ellipse_inside"] == 4 + 4  # card(P1) + card(P2)
    r = solve(problem)
    assert r.success, r.message
    ell = r.posture["contacts"][1]["ellipse"]
    assert ell is not None and r.posture["contacts"][1]["forces"] == []
    radii = sorted(ell["radii"], reverse=True)
    assert radii[0] >= 0.05 - 1e-9 and radii[1] >= 0.04 - 1e-9
    # the ellipse is inside both polygons: exact margin in the surface plane
    P_patch, P_step = _final_intersection(problem, r)
    e = Ellipse(np.array(ell["center_in_surface"]), ell["angle_in_surface"], tuple(ell["radii"]))
    assert e.inside_margin(P_patch) >= -1e-7 and e.inside_margin(P_step) >= -1e-7
    # a step 12 cm deep cannot hold the 20 cm foot: the contact is truly non-inclusive
    assert P_step.contains(P_patch.vertices, tol=1e-6).sum() < 4
    # the world-frame axes are consistent with the radii and lie in the step plane
    for axis, rad in zip(ell["axes"], ell["radii"], strict=True):
        assert np.linalg.norm(axis) == pytest.approx(rad)
        assert abs(axis[2]) < 1e-9


@pytest.mark.parametrize("formulation", ["support", "paper"])
def test_area_maximization_reaches_the_largest_ellipse(formulation):
    problem = problem_from_dict(
        step_problem({"type": "geometric", "formulation": formulation, "maximize_area": 10.0})
    )
    r = solve(problem)
    assert r.success, r.message
    area = np.pi * np.prod(r.posture["contacts"][1]["ellipse"]["radii"])
    best = largest_inscribed_ellipse(*_final_intersection(problem, r))
    assert area >= 0.99 * best.area
    assert area <= best.area * (1 + 1e-6)


def test_support_contact_bears_forces_on_the_ellipse_boundary(talos):
    problem = problem_from_dict(
        step_problem({"type": "support", "points": 8, "maximize_area": 1.0})
    )
    r = solve(problem)
    assert r.success, r.message
    c = r.posture["contacts"][1]
    assert len(c["forces"]) == 8
    centre = np.array(c["ellipse"]["center"])
    a1, a2 = (np.array(a) for a in c["ellipse"]["axes"])
    Minv = np.linalg.pinv(np.column_stack([a1, a2]))
    for f in c["forces"]:
        w = Minv @ (np.array(f["point"]) - centre)
        assert np.linalg.norm(w) == pytest.approx(1.0, abs=1e-7)  # on the ellipse's boundary
    # the step foot carries a real share of the weight
    fz = sum(f["force"][2] for f in c["forces"])
    assert fz > 0.05 * talos.weight


def test_inclusive_and_point_baselines():
    inc = problem_from_dict(step_problem({"type": "inclusive"}, depth=0.3))
    assert inc.constraint_counts()["contact.right_sole.inclusion"] == 4 * 4
    r = solve(inc)
    assert r.success, r.message
    P_patch, P_step = _final_intersection(inc, r)
    assert np.all(P_step.contains(P_patch.vertices, tol=1e-7))
    pt = problem_from_dict(step_problem({"type": "point", "point": [0.05, 0.0]}, depth=0.05))
    assert pt.constraint_counts()["contact.right_sole.point_inside"] == 4
    r = solve(pt)
    assert r.success, r.message
    p_world = np.array(r.posture["contacts"][1]["point"]["world"])
    assert p_world[2] == pytest.approx(0.1, abs=1e-7)


def test_inclusive_cannot_but_geometric_can():
    """A 5 cm deep step narrower than the foot in both directions: no inclusion exists."""
    data = step_problem({"type": "inclusive"}, depth=0.05, width=0.09)
    assert not solve(problem_from_dict(data)).success
    data = step_problem({"type": "geometric", "min_radii": [0.02, 0.02]}, depth=0.05, width=0.09)
    assert solve(problem_from_dict(data)).success


def test_next_stance_fixes_the_geometric_contact():
    problem = problem_from_dict(step_problem({"type": "geometric", "maximize_area": 5.0}))
    r = solve(problem)
    assert r.success, r.message
    nxt = next_problem(problem, r, fix="right_sole", release="left_sole")
    assert [c.type for c in nxt.contacts] == ["fixed"]
    fixed = nxt.contacts[0]
    P_patch, P_step = _final_intersection(problem, r)
    inter = intersect(P_patch, P_step)
    assert fixed.n_points == inter.n  # forces at the intersection's vertices (sec. IV-E)
    np.testing.assert_allclose(fixed.area.vertices, inter.vertices, atol=1e-9)
    np.testing.assert_allclose(nxt.q_init, r.q)
    # a geometric contact has no CoP margin: the fixed one takes the problem's
    assert fixed.cop_margin == DEFAULT_COP_MARGIN
    wider = dataclasses.replace(problem, cop_margin=0.02)
    assert next_problem(wider, r, fix="right_sole").contacts[1].cop_margin == 0.02
    r2 = solve(nxt)
    assert r2.success, r2.message
    assert r2.iterations < 60
    again = next_problem(nxt, r2, fix="right_sole")  # already fixed: it stays as it is
    assert again.contacts[0] is fixed
    np.testing.assert_allclose(again.q_init, r2.q)
    with pytest.raises(InputError, match="release"):
        next_problem(problem, r, fix="right_sole", release="nope")


def test_thin_rung_scaling_helps_the_paper_form():
    """Sec. IV-F: a rung 2.5 cm wide; the geometric scaling cuts the iterations (a failure
    counts as the iteration limit). With the scaling every case is solved."""
    iters = {}
    for scaling in ("auto", "none"):
        total = 0
        for x, h in ((0.25, 0.05), (0.3, 0.1), (0.35, 0.15)):
            data = step_problem(
                {
                    "type": "geometric",
                    "formulation": "paper",
                    "scaling": scaling,
                    "min_radii": [0.04, 0.008],
                },
                depth=0.025,
                x=x,
                height=h,
            )
            r = solve(problem_from_dict(data))
            if scaling == "auto":
                assert r.success, r.message
                radii = sorted(r.posture["contacts"][1]["ellipse"]["radii"])
                assert radii[0] <= 0.0125 + 1e-9  # no thicker than the rung
            total += r.iterations if r.success else 200
        iters[scaling] = total
    assert iters["auto"] < iters["none"]


def test_verify_rejects_an_ellipse_outside_or_too_small(talos):
    problem = problem_from_dict(step_problem({"type": "geometric", "min_radii": [0.04, 0.03]}))
    r = solve(problem)
    assert r.success
    bad = copy.deepcopy(r.posture)
    bad["contacts"][1]["ellipse"]["center"][0] += 0.1
    assert "contact points inside polygons" in {
        c.name for c in verify_posture(bad, talos.model).failures
    }
    bad = copy.deepcopy(r.posture)
    bad["contacts"][1]["ellipse"]["min_radii"] = [0.2, 0.1]
    assert "contact ellipse size" in {c.name for c in verify_posture(bad, talos.model).failures}


def test_yaw_range_turns_the_floating_foot_and_verify_checks_it(talos):
    """Free, the foot on the step keeps about the ground foot's heading; bounded to
    [0.4, 0.6] rad it turns into that range, and verify rejects a posture outside it."""
    free = solve(problem_from_dict(step_problem({"type": "support"}, depth=0.3)))
    assert free.success, free.message
    problem = problem_from_dict(step_problem({"type": "support", "yaw_range": [0.4, 0.6]}, 0.3))
    assert problem.constraint_counts()["contact.right_sole.yaw_range"] == 1
    r = solve(problem)
    assert r.success, r.message
    c = problem.contacts[1]
    free_yaw = c.realized_pose(talos.model, free.q)[1]  # in the step's frame
    yaw = c.realized_pose(talos.model, r.q)[1]
    assert not 0.4 <= free_yaw <= 0.6  # the bound is active: it changed the posture
    assert 0.4 - 1e-6 <= yaw <= 0.6 + 1e-6
    assert r.posture["contacts"][1]["yaw_range"] == [0.4, 0.6]
    bad = copy.deepcopy(r.posture)
    bad["contacts"][1]["yaw_range"] = [yaw + 0.05, yaw + 0.3]
    assert "contact geometry" in {c.name for c in verify_posture(bad, talos.model).failures}


@pytest.mark.parametrize(
    ("contact", "field"),
    [
        ({"type": "support", "yaw_range": [0.5, -0.5]}, "contacts[1].yaw_range"),
        ({"type": "geometric", "yaw_range": [0.0, 7.0]}, "contacts[1].yaw_range"),
        ({"type": "inclusive", "yaw_range": [0.0]}, "contacts[1].yaw_range"),
        ({"type": "geometric", "formulation": "exact"}, "contacts[1].formulation"),
        ({"type": "geometric", "min_radii": [0.1, -0.1]}, "contacts[1].min_radii"),
        ({"type": "geometric", "position": [0, 0]}, "contacts[1].position"),
        ({"type": "support", "points": 3}, "contacts[1].points"),
        ({"type": "point", "point": [1.0, 0.0]}, "contacts[1].point"),
        ({"type": "geometric", "maximize_area": -1}, "contacts[1].maximize_area"),
        ({"type": "geometric", "scaling": "huge"}, "contacts[1].scaling"),
    ],
)
def test_contact_options_are_validated(contact, field):
    with pytest.raises(InputError) as info:
        problem_from_dict(step_problem(contact))
    assert str(info.value).startswith(field)


@pytest.mark.parametrize(
    ("kind", "faces", "field"),
    [("cones", 4, "friction.model"), ("Pyramid", 4, "friction.model"), ("pyramid", 2, "faces")],
)
def test_an_unknown_friction_model_is_an_input_error(kind, faces, field):
    """FrictionModel("cones") used to build a pyramid silently."""
    with pytest.raises(InputError) as info:
        FrictionModel(kind, faces)
    assert str(info.value).startswith(f"friction.{field.split('.')[-1]}")
    assert FrictionModel("cone").constraints(ca.SX.sym("phi", 3), ca.SX(0.5)).shape == (1, 1)
