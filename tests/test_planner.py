"""The contact planner (posturegen.planner): a stairs plan found and verified, the goal and
rules formats' one-line errors, the target picking and the heuristic's goal test."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pinocchio as pin
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen import plan
from posturegen.cli import main
from posturegen.errors import InputError
from posturegen.model.geometry import ConvexPolygon
from posturegen.model.robot import load_bundled
from posturegen.model.scene import Obstacle, Scene, Surface
from posturegen.planner import Budget, Goal, default_rules, parse_goal, parse_rules
from posturegen.planner.command import write_figures
from posturegen.planner.heuristic import FOCAL, STEP_COST, Heuristic
from posturegen.planner.layout import HEADROOM, Region, pick_target, regions
from posturegen.planner.node import FREE, Action, Node, place_of
from posturegen.planner.rules import is_hand
from posturegen.planner.search import REVISIT, Search, _Entry
from posturegen.planner.solver import RoundSolver
from posturegen.verify import verify_posture
from tests.plan_checks import assert_exact_unloads

PATCHES = ["left_sole", "right_sole", "left_hand", "right_hand"]
SURFACES = ["ground", "step1", "step2"]
FRAMES = ["base_link", "l_foot"]


def test_stairs_plan_reaches_the_top_with_every_stage_verified(tmp_path):
    """Talos, 2 steps, no stage list: both soles end on step 2, every posture re-checked.
    The plan learns its own active sets: the process's are as they were after it."""
    from posturegen.solver import solve as solve_module

    outer = solve_module._LEARNED
    outer.put(("a problem solved before the plan",), (frozenset(), frozenset(), None))
    n_outer = len(outer)
    report = plan("stairs", tmp_path, robot="talos", steps=2, budget=Budget(nodes=20))
    assert solve_module._LEARNED is outer and len(outer) == n_outer
    assert report.success and report.stats.reached
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert index["success"] and len(index["stages"]) >= 5
    robot = load_bundled("talos")
    for stage in index["stages"]:
        posture = json.loads((tmp_path / stage["posture"]).read_text())
        assert stage["success"] and posture["self_collision"]
        assert verify_posture(posture, robot.model).ok, stage["name"]
    last = json.loads((tmp_path / index["stages"][-1]["posture"]).read_text())
    held = {(c["robot_patch"]["name"], c["surface"]["name"]) for c in last["contacts"]}
    assert {("left_sole", "step2"), ("right_sole", "step2")} <= held
    summary = json.loads((tmp_path / "plan.json").read_text())
    assert summary["reached"] and summary["postures_solved"] >= len(index["stages"])
    assert summary["stances"][-1] == "left_sole@step2, right_sole@step2"
    # every removal unloaded exactly: the patch within 1 mm of where the stance before held
    # it, bearing nothing
    assert summary["unloads"] >= 1
    assert_exact_unloads(tmp_path, index["stages"], robot)
    # where the time went: the parts add up to the whole; with one worker the postures'
    # solver, build and re-check times fit in the rounds' wall time
    t = summary["time"]
    assert t["postures_s"] + t["search_s"] + t["files_s"] == pytest.approx(t["total_s"], abs=2e-3)
    assert 0 < t["solver_s"] and 0 < t["verify_s"]
    assert t["solver_s"] + t["build_s"] + t["verify_s"] + t["other_s"] <= t["postures_s"] + 2e-3
    # the plan's viewer and contact sheet, as `posturegen plan` writes them
    (line,) = write_figures(tmp_path)
    html, png = tmp_path / "plan.html", tmp_path / "plan.png"
    assert "plan.html" in line and html.stat().st_size > 100_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


@pytest.mark.parametrize(
    "goal, field",
    [
        (
            {"contacts": [{"robot_patch": "left_sole", "surface": "step9"}]},
            "goal.contacts[0].surface",
        ),
        (
            {"contacts": [{"robot_patch": "left_foot", "surface": "step1"}]},
            "goal.contacts[0].robot_patch",
        ),
        ({"contacts": [{"robot_patch": "left_sole"}]}, "goal.contacts[0].surface"),
        ({"contacts": []}, "goal.contacts"),
        ({"frame": "base_link", "point": [1, 2]}, "goal.point"),
        ({"frame": "base_lnk", "point": [1, 2, 3]}, "goal.frame"),
        ({"frame": "base_link", "point": [1, 2, 3], "tolerance": -1}, "goal.tolerance"),
        ({"point": [1, 2, 3]}, "goal"),
        ([1, 2], "goal"),
    ],
)
def test_goal_errors_name_their_field(goal, field):
    with pytest.raises(InputError) as exc:
        parse_goal(goal, PATCHES, SURFACES, FRAMES)
    assert exc.value.field == field and "\n" not in str(exc.value)


def test_goal_formats_round_trip():
    g = parse_goal({"frame": "base_link", "point": [1, 0, 1.2]}, PATCHES, SURFACES, FRAMES)
    assert g.frame == "base_link" and g.tolerance == 0.05
    assert parse_goal(g.to_dict(), PATCHES, SURFACES, FRAMES) == g
    c = {"contacts": [{"robot_patch": "left_sole", "surface": "step2"}]}
    assert parse_goal(c, PATCHES, SURFACES, FRAMES).to_dict() == c


@pytest.fixture(scope="module")
def atlas_rules():
    return default_rules(load_bundled("atlas"), SURFACES)


@pytest.mark.parametrize(
    "rules, field",
    [
        ({"patches": {"left_foot": {}}}, "rules.patches.left_foot"),
        ({"min_contacts": 3, "max_contacts": 2}, "rules.max_contacts"),
        ({"hands": "yes"}, "rules.hands"),
        ({"patches": {"left_sole": {"reach": -0.2}}}, "rules.patches.left_sole.reach"),
        (
            {"patches": {"left_sole": {"contact": {"radii": [0.1]}}}},
            "rules.patches.left_sole.contact.radii",
        ),
        ({"patches": {"left_sole": {"surfaces": []}}}, "rules.patches.left_sole.surfaces"),
        ({"max_contact": 3}, "rules.max_contact"),
        ({"min_contacts": 0}, "rules.min_contacts"),
        ({"release": "drop"}, "rules.release"),
    ],
)
def test_rule_errors_name_their_field(atlas_rules, rules, field):
    with pytest.raises(InputError) as exc:
        parse_rules(rules, atlas_rules)
    assert exc.value.field == field and "\n" not in str(exc.value)


def test_rules_override_the_defaults(atlas_rules):
    r = parse_rules({"hands": True, "patches": {"left_hand": {"surfaces": ["step*"]}}}, atlas_rules)
    assert r.hands and "left_hand" in r.movable()
    assert r.patches["left_hand"].allows("step2") and not r.patches["left_hand"].allows("ground")
    assert "left_hand" not in atlas_rules.movable()  # hands off by default


def test_cli_bad_goal_is_one_line(tmp_path, capsys):
    goal = json.dumps({"contacts": [{"robot_patch": "left_sole", "surface": "step9"}]})
    code = main(["plan", "stairs", "--steps", "1", "--goal", goal, "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "goal.contacts[0].surface" in err and "\n" not in err


rect = st.tuples(
    st.floats(0.02, 1.0), st.floats(0.02, 1.0), st.floats(-1, 1), st.floats(-1, 1), st.floats(0, 1)
)


@settings(max_examples=60, deadline=None)
@given(
    rect,
    st.lists(st.tuples(*[st.floats(-1.5, 1.5)] * 3), min_size=1, max_size=3),
    st.tuples(*[st.floats(-2, 2)] * 3),
    st.floats(0.05, 2.0),
)
def test_picked_target_lies_on_the_surface_within_reach(r, anchors, spot, reach):
    """A target is inside the polygon, in its plane, within reach of an anchor, and no
    point of a grid over the polygon within reach is nearer the spot (to the 32-gon's
    0.5 % of the reach); None only when no grid point is within reach."""
    sx, sy, x, y, z = r
    v = [[-sx / 2, -sy / 2], [sx / 2, -sy / 2], [sx / 2, sy / 2], [-sx / 2, sy / 2]]
    T = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 0.5), np.array([x, y, z]))
    region = Region.of(Surface("s", T, ConvexPolygon(v)))
    anchors_ = [np.array(a) for a in anchors]
    target = pick_target(region, np.array(spot), anchors_, reach)
    inner = region.inner()
    x0, y0, x1, y1 = inner.bounds
    gx, gy = np.meshgrid(np.linspace(x0, x1, 15), np.linspace(y0, y1, 15))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    grid = region.surface.to_world(grid[shapely.contains_xy(inner, grid[:, 0], grid[:, 1])])
    near = [p for p in grid if min(np.linalg.norm(p - a) for a in anchors_) <= 0.99 * reach]
    if target is None:
        assert not near
        return
    assert region.distance(target) < 1e-9
    assert min(np.linalg.norm(target - a) for a in anchors_) <= reach + 1e-9
    if near:
        best = min(np.linalg.norm(p - np.array(spot)) for p in near)
        assert np.linalg.norm(target - np.array(spot)) <= best + 1e-9


@settings(max_examples=60, deadline=None)
@given(
    st.tuples(
        st.floats(0.05, 0.6), st.floats(0.05, 0.6), st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)
    ),
    st.floats(-0.05, 0.5),
    st.lists(st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2)), min_size=1, max_size=2),
    st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)),
)
def test_no_target_under_a_low_solid_nor_behind_it(box, underside, anchors, spot):
    """A box over the ground lower than HEADROOM: no target in its footprint, and the straight
    path from some anchor within reach to the target does not cross it; a box higher than
    HEADROOM (or sunk under the ground) takes nothing away."""
    sx, sy, x, y = box
    ground = Surface(
        "ground",
        pin.SE3.Identity(),
        ConvexPolygon([[-1.5, -1.5], [1.5, -1.5], [1.5, 1.5], [-1.5, 1.5]]),
    )
    T_box = pin.SE3(np.eye(3), np.array([x, y, underside + 0.05]))
    scene = Scene({"ground": ground}, (Obstacle("box", np.array([sx, sy, 0.1]), T_box),))
    region = regions(scene)["ground"]
    foot = shapely.box(x - sx / 2, y - sy / 2, x + sx / 2, y + sy / 2)
    anchors_ = [np.array([a, b, 0.0]) for a, b in anchors if not foot.contains(shapely.Point(a, b))]
    reach = 0.7
    target = pick_target(region, np.array([*spot, 0.0]), anchors_, reach)
    cut = -0.1 < underside < HEADROOM
    assert len(region.cuts) == int(cut)
    if target is None:
        return
    point = shapely.Point(target[0], target[1])
    if not cut:
        return
    assert foot.distance(point) > 1e-6
    if not anchors_:  # no reach to keep: any point of the ground less the cut
        return
    paths = [
        shapely.LineString([a[:2], target[:2]])
        for a in anchors_
        if np.linalg.norm(target - a) <= reach + 1e-9
    ]
    assert any(p.intersection(foot).length < 1e-9 for p in paths)


def test_a_stairs_ground_target_is_never_under_a_step():
    """ATLAS' stairs: from soles anywhere in front of the stairs, the ground's target nearest
    the top step is in front of the first step or beside the flight, never under it."""
    scene = Scene(
        {
            "ground": Surface(
                "ground",
                pin.SE3.Identity(),
                ConvexPolygon([[-1.5, -1.5], [1.5, -1.5], [1.5, 1.5], [-1.5, 1.5]]),
            ),
            **{
                f"step{k}": Surface(
                    f"step{k}",
                    pin.SE3(np.eye(3), np.array([0.4567 + 0.163 * (k - 1), 0, 0.12 * k])),
                    ConvexPolygon([[-0.0815, -0.4], [0.0815, -0.4], [0.0815, 0.4], [-0.0815, 0.4]]),
                    thickness=0.12,
                )
                for k in range(1, 5)
            },
        }
    )
    areas = regions(scene)
    flight = shapely.box(0.4567 - 0.0815, -0.4, 0.9457 + 0.0815, 0.4)
    rng = np.random.default_rng(3)
    for _ in range(40):
        anchor = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 0.08])
        target = pick_target(areas["ground"], areas["step4"].centre(), [anchor], 0.693)
        assert target is not None
        assert flight.distance(shapely.Point(target[0], target[1])) > 0.05


def _steps_heuristic():
    """Ground, step1, step2 (30 cm apart, 12 cm rise); goal: both soles on step2."""
    surfaces = {
        n: Surface(
            n,
            pin.SE3(np.eye(3), np.array([0.3 * k, 0, 0.12 * k])),
            ConvexPolygon([[-0.1, -0.4], [0.1, -0.4], [0.1, 0.4], [-0.1, 0.4]]),
        )
        for k, n in enumerate(SURFACES)
    }
    areas = {n: Region.of(s) for n, s in surfaces.items()}
    goal = Goal(contacts=(("left_sole", "step2"), ("right_sole", "step2")))
    spots = {p: areas["step2"].centre() for p in PATCHES}
    return Heuristic(goal, areas, spots, 2)


def test_heuristic_is_zero_exactly_when_the_goal_contacts_are_held():
    heur = _steps_heuristic()
    pos = {p: np.zeros(3) for p in PATCHES}
    start = frozenset({("left_sole", "ground"), ("right_sole", "ground")})
    top = frozenset({("left_sole", "step2"), ("right_sole", "step2")})
    half = frozenset({("left_sole", "step2"), ("right_sole", "ground")})
    assert heur.h(top, pos, None) == 0.0 and heur.reached(top, None)
    assert heur.h(start, pos, None) > heur.h(half, pos, None) > 0 and not heur.reached(half, None)
    assert heur.f(0.0, 0.0, frozenset({("left_sole", "step2")})) > heur.f(0.0, 0.0, top)


def _stances():
    """Every stance of the two soles on SURFACES (at least one contact)."""
    options = [None, *SURFACES]
    out = []
    for a, b in itertools.product(options, options):
        key = frozenset((p, s) for p, s in zip(PATCHES[:2], (a, b), strict=True) if s is not None)
        if key:
            out.append(key)
    return out


def _neighbours(key):
    """Stances one transition away: a sole added on a surface, or removed (one left)."""
    on = dict(key)
    out = [key - {(p, s)} for p, s in key if len(key) > 1]
    out += [key | {(p, s)} for p in PATCHES[:2] if p not in on for s in SURFACES]
    return out


def test_the_focal_bound_is_admissible_and_consistent():
    """bound(stance) <= STEP_COST × the fewest transitions to the goal (breadth-first over
    every stance), and changes by at most STEP_COST along a transition."""
    heur = _steps_heuristic()
    stances = _stances()
    goal = frozenset(heur.goal.contacts)
    dist = {k: 0 for k in stances if goal <= k}
    frontier = list(dist)
    while frontier:  # transitions are reversible: breadth-first from the goal stances
        nxt = []
        for k in frontier:
            for n in _neighbours(k):
                if n not in dist:
                    dist[n] = dist[k] + 1
                    nxt.append(n)
        frontier = nxt
    assert set(dist) == set(stances)
    for k in stances:
        assert heur.bound(k) <= STEP_COST * dist[k] + 1e-12, sorted(k)
        for n in _neighbours(k):
            assert abs(heur.bound(k) - heur.bound(n)) <= STEP_COST + 1e-12
    assert heur.bound(frozenset({("left_sole", "ground"), ("right_sole", "ground")})) > 0


def test_a_transition_away_from_the_goal_costs_more_than_one_towards_it():
    heur = _steps_heuristic()
    assert heur.cost(0.5, 0.3, False) == STEP_COST
    assert heur.cost(0.3, 0.5, False) == pytest.approx(STEP_COST + 0.2)
    assert heur.cost(0.5, 0.3, True) > heur.cost(0.5, 0.3, False)


def _search_on_steps(rules):
    return Search({}, _steps_heuristic(), rules, RoundSolver(1), Budget())


@settings(max_examples=40, deadline=None)
@given(
    st.dictionaries(st.sampled_from(PATCHES[:2]), st.sampled_from(SURFACES), min_size=1),
    st.sampled_from(["add", "remove"]),
    st.floats(0.1, 1.0),
)
def test_successors_follow_the_rules_and_never_undo(on, kind, reach):
    """Removes keep min_contacts; adds put a free sole on an allowed surface within reach
    of a sole in contact; no successor undoes the transition that led to the node."""
    rules = parse_rules(
        {"patches": {p: {"reach": reach, "surfaces": ["ground", "step*"]} for p in PATCHES[:2]}},
        default_rules(load_bundled("atlas"), SURFACES),
    )
    search = _search_on_steps(rules)
    key = frozenset(on.items())
    p0, s0 = sorted(on.items())[0]
    last = Action(kind, p0, s0)
    positions = {
        p: np.array([0.3 * SURFACES.index(on.get(p, "ground")), 0.0, 0.0]) for p in PATCHES
    }
    node = Node(key, {p: p for p in on}, (), positions, action=last)
    for a in search._actions(node):
        assert (a.patch, a.surface) != (p0, s0)
        if a.kind == "remove":
            assert len(on) > rules.min_contacts and on[a.patch] == a.surface
        else:
            assert a.patch not in on and rules.patches[a.patch].allows(a.surface)
            assert not is_hand(a.patch)
            d = min(np.linalg.norm(np.array(a.target) - positions[p]) for p in on)
            assert d <= reach + 1e-9


def test_the_focal_list_keeps_the_bound_then_orders_by_distance():
    """Open: A (g + bound 0.2, order 5), B (0.5, 1), C (0.7, 0.5). With FOCAL 3 the first
    pick is B (the best order within 3 × 0.2), not C (best order, beyond the bound); then A
    (C still beyond); then C."""
    rules = default_rules(load_bundled("atlas"), SURFACES)
    search = _search_on_steps(rules)
    node = Node(frozenset({("left_sole", "ground")}), {}, (), {p: np.zeros(3) for p in PATCHES})
    action = Action("remove", "left_sole", "ground")
    for name, bounded, order in (("A", 0.2, 5.0), ("B", 0.5, 1.0), ("C", 0.7, 0.5)):
        child = frozenset({(name, "ground", (0, 0, 0))})
        entry = _Entry(bounded, order, 1, next(search._count), node, action, child, 0.05)
        search._open.append(entry)
    assert FOCAL == 3.0
    picks = [next(iter(search._pop_focal(set()).child))[0] for _ in range(3)]
    assert picks == ["B", "A", "C"] and search._pop_focal(set()) is None


def test_no_add_puts_a_patch_back_where_the_path_took_it_off():
    """A sole taken off step1 at x = 0.3 is not offered step1 within REVISIT of that point
    again (further along the step it is), nor anywhere on step1 once it is pruned there."""
    rules = parse_rules(
        {"patches": {p: {"reach": 1.0, "surfaces": ["ground", "step*"]} for p in PATCHES[:2]}},
        default_rules(load_bundled("atlas"), SURFACES),
    )
    search = _search_on_steps(rules)
    at = {p: np.array([0.3, 0.0, 0.12]) for p in PATCHES}
    both = frozenset({("left_sole", "step1"), ("right_sole", "step1")})
    start = Node(both, {}, (), at)
    off = Action("remove", "right_sole", "step1")
    moved = dict(at, left_sole=np.array([0.6, 0.1, 0.24]))
    left = Node(both - {("right_sole", "step1")}, {}, (), at, parent=start, action=off)
    # the left sole moved on to step2 since: the right sole's spot on step1 is unchanged
    later = Node(
        frozenset({("left_sole", "step2")}),
        {},
        (),
        moved,
        parent=left,
        action=Action("add", "left_sole", "step2"),
    )
    adds = [a for a in search._actions(later) if a.kind == "add" and a.patch == "right_sole"]
    assert adds  # step2 (and ground) are still offered
    for a in adds:
        if a.surface == "step1":
            assert np.linalg.norm(np.array(a.target) - at["right_sole"]) >= REVISIT


def test_a_problem_files_stance_walks_to_a_frame_goal(tmp_path):
    """Start: a problem file's two fixed soles; goal: the base 0.3 m forward (a frame goal).
    The plan steps forward on the ground; its last posture's base is within the tolerance,
    every stage verified."""
    robot = load_bundled("talos")
    start = tmp_path / "start.yaml"
    start.write_text(
        "robot: talos\nmu: 0.7\n"
        "surfaces:\n  - {name: ground, vertices: [[-1, -1], [1.5, -1], [1.5, 1], [-1, 1]]}\n"
        "contacts:\n"
        "  - {robot_patch: left_sole, surface: ground, type: fixed, position: [0.0, 0.085]}\n"
        "  - {robot_patch: right_sole, surface: ground, type: fixed, position: [0.0, -0.085]}\n"
    )
    point = [0.3, 0.0, float(robot.q_init[2])]
    goal = {"frame": "base_link", "point": point, "tolerance": 0.08, "weight": 0.3}
    report = plan(str(start), tmp_path / "out", goal=goal, budget=Budget(nodes=20))
    assert report.success and report.stats.reached
    index = json.loads((tmp_path / "out" / "sequence.json").read_text())
    stances = json.loads((tmp_path / "out" / "plan.json").read_text())["stances"]
    assert {"left_sole@ground", "right_sole@ground"} <= set(stances)  # each foot alone once
    assert len(stances) >= 5  # the base cannot move 0.3 m over fixed feet: both feet step
    last = None
    for stage in index["stages"]:
        last = json.loads((tmp_path / "out" / stage["posture"]).read_text())
        assert stage["success"] and verify_posture(last, robot.model).ok, stage["name"]
    q = np.array(last["q"])
    assert np.linalg.norm(q[:3] - point) <= 0.08
    held = {c["robot_patch"]["name"] for c in last["contacts"]}
    assert {"left_sole", "right_sole"} <= held


def test_a_goal_out_of_reach_ends_naming_the_best_stance_and_what_blocked_it(tmp_path, capsys):
    """Both soles to a shelf 1.6 m up: no stance reaches it; the command ends within its
    budget (exit 1), naming the best stance and, per goal contact, the reach that kept it
    off; plan.json says the same."""
    start = tmp_path / "start.yaml"
    start.write_text(
        "robot: talos\nmu: 0.7\n"
        "surfaces:\n  - {name: ground, vertices: [[-1, -1], [1.5, -1], [1.5, 1], [-1, 1]]}\n"
        "  - {name: shelf, position: [0.6, 0, 1.6], vertices: [[-0.2, -0.4], [0.2, -0.4], "
        "[0.2, 0.4], [-0.2, 0.4]]}\n"
        "contacts:\n"
        "  - {robot_patch: left_sole, surface: ground, type: fixed, position: [0.0, 0.085]}\n"
        "  - {robot_patch: right_sole, surface: ground, type: fixed, position: [0.0, -0.085]}\n"
    )
    goal = json.dumps(
        {"contacts": [{"robot_patch": p, "surface": "shelf"} for p in ("left_sole", "right_sole")]}
    )
    out = tmp_path / "out"
    args = ["plan", str(start), "--goal", goal, "--out", str(out), "--budget-nodes", "2"]
    code = main([*args, "--quiet", "--no-figures"])
    printed = capsys.readouterr().out
    assert code == 1 and "NOT reached" in printed
    summary = json.loads((out / "plan.json").read_text())
    assert not summary["reached"] and summary["transitions_tried"] <= 2
    assert (
        summary["best"] in summary["stances"] and f"best stance found: {summary['best']}" in printed
    )
    assert len(summary["blocked"]) == 2
    for line in summary["blocked"]:
        assert "shelf: beyond the patch's reach" in line and line in printed


def test_a_bad_posture_budget_is_one_line(tmp_path, capsys):
    code = main(["plan", "stairs", "--budget-iter", "0", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "budget.posture_iterations" in err and "\n" not in err


def test_a_free_patch_is_part_of_the_place_it_left():
    """A stance's place records where each patch taken off it left: one sole on step 2 with
    the other lifted from the ground is not the place of the other lifted from step 1 (the
    next touch is another problem), and placing the patch again forgets where it left."""
    positions = {
        "left_sole": np.array([0.5, 0.1, 0.4]),
        "right_sole": np.array([0.0, -0.1, 0.0]),
    }
    key = frozenset({("left_sole", "step2"), ("right_sole", "ground")})
    start = Node(key, {}, (), positions)
    off = Action("remove", "right_sole", "ground")
    left = off.child_left(start.left, positions)
    assert left == {"right_sole": ("ground", (0, -1, 0))}
    child = place_of(off.child_key(key), positions, left)
    assert child == off.child_place(start.place)
    from_step1 = {**positions, "right_sole": np.array([0.3, -0.1, 0.2])}
    other = Node(frozenset({("left_sole", "step2"), ("right_sole", "step1")}), {}, (), from_step1)
    off1 = Action("remove", "right_sole", "step1")
    assert off1.child_place(other.place) != child  # the same stance, another place
    on = Action("add", "right_sole", "step2", (0.5, -0.1, 0.4))
    again = on.child_place(child)
    assert {p for p, _, _ in again} == {"left_sole", "right_sole"}
    assert not any(s.startswith(FREE) for _, s, _ in again)
    assert on.child_left(left, positions) == {}


def test_inside_own_learning_solves_start_from_no_learned_active_set():
    """posturegen.solver.solve.own_learning: an empty set of learned active sets inside, the
    process's back after, what was learned inside forgotten."""
    from posturegen.solver import solve as solve_module

    outer = solve_module._LEARNED
    outer.put(("before",), (frozenset(), frozenset(), None))
    with solve_module.own_learning():
        inner = solve_module._LEARNED
        assert inner is not outer and len(inner) == 0
        inner.put(("inside",), (frozenset(), frozenset(), None))
    assert solve_module._LEARNED is outer
    assert ("before",) in outer and ("inside",) not in outer
