"""Collision rows in slots whose pairs are parameters (posturegen.collision.slots): one program
per robot and capacity serves every active set. The rows must be the held pairs' smooth minima
whatever block and capacity hold them, free blocks and rows must change nothing, and a
structure's later problems, whatever their active sets, must build nothing."""

from __future__ import annotations

import copy
import importlib

import casadi as ca
import numpy as np
import pinocchio as pin
import yaml

from posturegen import clear_caches, problem_from_dict
from posturegen.cli import _demo_dir
from posturegen.collision.boxes import row_box_distances
from posturegen.collision.rows import CollisionTerm
from posturegen.collision.self_blocks import CLAMP
from posturegen.collision.slots import FREE_ROW, Capacity
from posturegen.collision.soft_min import ENV_SATURATION, SOFT_MIN_BETA
from posturegen.collision.stance_hold import held_clearance
from posturegen.solver import compile as compile_module
from posturegen.solver.problem import Program
from posturegen.solver.solve import configuration_from_x
from posturegen.terms.nlp import NLP, BuildContext

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
solve_module = importlib.import_module("posturegen.solver.solve")


def _soft_min(v: np.ndarray, beta: float) -> float:
    m = v.min()
    return float(m - np.log(np.exp(-beta * (v - m)).sum()) / beta)


def _problem(target, box=True):
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = target
    data["options"]["self_collision"] = True
    if box:
        data["obstacles"] = [
            {"name": "box", "box": [0.2, 0.2, 0.2], "position": [0.45, -0.3, 0.95]}
        ]
    return problem_from_dict(data)


def _solved_program(problem):
    """The program of the last IPOPT run of ``problem``'s solve (its collision rows held)."""
    result, runs = solve_module._solve_continued(Program.of(problem), None, [])
    assert result.success, result.message
    return runs[-1].program


def _numpy_rows(program, term, q):
    """Each self row: softmin over its held pairs of |c_i - c_j| - r_i - r_j - held (NaN for a
    free row); each env row: softmin(d_row, margin + ENV_SATURATION) - margin (NaN for a free
    slot); and the smallest held self distance (the rows' shared shift)."""
    model = program.robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pm = term.pm
    centers = pm.centers_world(model, data)
    held = held_clearance(program, pm, term.margin)
    self_rows, smallest = [], np.inf
    for _, members in term.self_groups():
        if not members:
            self_rows.append(np.nan)
            continue
        pairs = np.array(members)
        d = pm.distances(centers, pairs[:, 0], pairs[:, 1])
        links = [pm.link_index(pm.joint_ids[i], pm.joint_ids[j]) for i, j in members]
        self_rows.append(_soft_min(d - held[links], SOFT_MIN_BETA))
        smallest = min(smallest, float((d - held[links]).min()))
    d_env = row_box_distances(pm, centers, term.boxes)
    env_rows = [
        np.nan
        if pair is None
        else _soft_min(np.array([d_env[pair], term.margin + ENV_SATURATION]), SOFT_MIN_BETA)
        - term.margin
        for pair in term.env_rows()
    ]
    return np.array(self_rows), np.array(env_rows), smallest


def _rows(program, x):
    compiled = program.compile()
    _, p, lbg, _ = program.numeric(compiled)
    g = np.array(compiled.nlp(x, p)[1]).ravel()
    return (
        g[compiled.g_index["collision.self"]],
        g[compiled.g_index["collision.env"]],
        lbg[compiled.g_index["collision.self"]],
        lbg[compiled.g_index["collision.env"]],
    )


def _wider(term: CollisionTerm) -> CollisionTerm:
    """``term``'s pairs in twice its capacity."""
    capacity = Capacity(2 * term.capacity.self_blocks, 2 * term.capacity.env_slots)
    return CollisionTerm(
        term.pm, term.self_pairs, term.env_pairs, term.boxes, term.margin, capacity
    )


def test_rows_are_the_held_pairs_smooth_minima_in_any_capacity():
    """At seeded random postures the program's rows equal numpy's smooth minima of the held
    pairs (up to the shared shift's clamp), in the capacity the solve grew and in twice it:
    free rows are the constant FREE_ROW (self) or 0 (env), unbounded; live rows the same to
    1e-9."""
    problem = _problem([0.45, -0.3, 0.75])
    program = _solved_program(problem)
    term = program.collision_term
    assert term.self_pairs and term.env_pairs
    wide_term = _wider(term)
    wide = program.but(collision_term=wide_term)
    compiled = program.compile()
    x_sol, _, _, _ = program.numeric(compiled)
    rng = np.random.default_rng(5)
    for k in range(6):
        x = x_sol + (0 if k == 0 else 0.2) * rng.normal(size=x_sol.size)
        q = configuration_from_x(program, compiled, x)
        for prog, t in ((program, term), (wide, wide_term)):
            want_self, want_env, smallest = _numpy_rows(prog, t, q)
            g_self, g_env, lb_self, lb_env = _rows(prog, x)
            live_self, live_env = np.isfinite(want_self), np.isfinite(want_env)
            near = live_self & (want_self < smallest + CLAMP - 0.05)
            np.testing.assert_allclose(g_self[near], want_self[near], atol=1e-9)
            # a row far above the closest one is read at the clamp: a lower bound, positive
            assert np.all(g_self[live_self] <= want_self[live_self] + 1e-9)
            np.testing.assert_allclose(g_env[live_env], want_env[live_env], atol=1e-9)
            np.testing.assert_array_equal(g_self[~live_self], FREE_ROW)
            np.testing.assert_array_equal(g_env[~live_env], 0.0)
            assert np.all(lb_self[live_self] == 0) and np.all(lb_self[~live_self] == -np.inf)
            assert np.all(lb_env[live_env] == 0) and np.all(lb_env[~live_env] == -np.inf)
        assert (~np.isfinite(_numpy_rows(wide, wide_term, q)[1])).sum() > 0  # free slots seen


def test_free_slots_change_no_posture():
    """The same pairs solved in their capacity and in twice it: the same posture."""
    program = _solved_program(_problem([0.45, -0.3, 0.75]))
    narrow = solve_module.run_nlp(program, None)[-1]
    wide = solve_module.run_nlp(program.but(collision_term=_wider(program.collision_term)), None)[
        -1
    ]
    assert narrow.status == wide.status == "Solve_Succeeded"
    q_narrow = configuration_from_x(program, narrow.compiled, narrow.x)
    q_wide = configuration_from_x(program, wide.compiled, wide.x)
    np.testing.assert_allclose(q_wide, q_narrow, atol=1e-7)
    assert abs(wide.iterations - narrow.iterations) <= 1


def test_a_structures_later_problems_build_nothing(monkeypatch):
    """Reaches of one structure whose active sets differ: the first problem makes the
    structure's program, every later one (other pairs held, other rounds) makes none, and
    every posture is verified. (No round's posture stands on its meshes here: the rounds
    go on, holding more pairs.)"""
    monkeypatch.setattr(solve_module._Loop, "standing", lambda self, scan: None)
    targets = [
        [0.3, -0.3, 0.8],
        [0.2, -0.1, 0.9],
        [0.35, -0.4, 0.7],
        [0.15, -0.2, 1.0],
        [0.25, 0.05, 0.95],
    ]
    problems = [_problem(t, box=False) for t in targets]
    clear_caches()  # this process's first problem of the structure
    made, held = [], set()
    for problem in problems:
        before = sum(compile_module.MADE.values())
        result, runs = solve_module._solve_continued(Program.of(problem), None, [])
        assert result.success, result.message
        made.append(sum(compile_module.MADE.values()) - before)
        held |= {run.program.collision_term.self_pairs for run in runs}
    assert len(held) >= 3  # the runs held other pairs: once, other programs
    assert made[0] > 0 and made[1:] == [0] * (len(problems) - 1), made


def test_late_rows_stand_where_their_term_stands():
    """The collision term is declared on a cached program of the other terms (Term.late), yet
    its blocks take its place in Program.terms(): the program equals one declared term after
    term (IPOPT's path follows the row order: with the collision rows last, HRP-2's vertical
    ladder failed at 'left foot on rung 2')."""
    program = _solved_program(_problem([0.3, -0.3, 0.8]))
    assert program.collision_term is not None and program.terms()[-1] is not program.collision_term
    ctx = BuildContext(robot=program.robot, nlp=NLP(), kin=program.robot.kinematics)
    for term in program.terms():
        term.declare(ctx)
    compiled = program.compile()
    assert list(compiled.g_index) == list(ctx.nlp.g)
    assert list(compiled.x_index) == list(ctx.nlp.x)
    assert list(compiled.p_index) == list(ctx.nlp.p)
    x0, p, _, _ = program.numeric(compiled)
    x = ca.vertcat(*[v[0] for v in ctx.nlp.x.values()])
    g = ca.vertcat(*[v[0] for v in ctx.nlp.g.values()])
    fresh = ca.Function("g", [x, ca.vertcat(*ctx.nlp.p.values())], [g])
    np.testing.assert_array_equal(
        np.array(fresh(x0, p)).ravel(), np.array(compiled.nlp(x0, p)[1]).ravel()
    )
