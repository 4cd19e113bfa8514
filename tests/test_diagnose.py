"""The diagnosis of a failure (posturegen.terms.elastic, posturegen.solver.diagnose): each cause on
a
problem built to have it, its amount checked against the problem, and the elastic program's
derivatives."""

from __future__ import annotations

import copy
import dataclasses
import json

import casadi as ca
import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from posturegen.cli import _demo_dir, main
from posturegen.collision.active_set import ActiveSet
from posturegen.collision.rows import CollisionTerm
from posturegen.errors import ImplausibleValueWarning
from posturegen.io.problem_file import problem_from_dict
from posturegen.solver.compile import symbolic
from posturegen.solver.diagnose import (
    Diagnosis,
    diagnose,
    from_rejection,
    from_relaxed,
    relax,
    required_mu,
)
from posturegen.solver.problem import Program
from posturegen.solver.solve import solve
from posturegen.terms.elastic import Elastic, category
from posturegen.terms.friction import FrictionModel
from posturegen.verify import Check, VerifyReport

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
WALL = {
    "name": "wall",
    "position": [3.0, 0.3, 1.0],
    "rpy": [0, -np.pi / 2, 0],  # normal towards the robot (-x)
    "vertices": [[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]],
}


def _problem(edit: dict) -> dict:
    data = copy.deepcopy(STAND)
    for key, value in edit.items():
        node = data
        *path, last = key.split(".")
        for k in path:
            node = node[int(k)] if k.isdigit() else node[k]
        node[last] = value
    return data


def _diagnose(data: dict) -> tuple[object, dict]:
    problem = problem_from_dict(data)
    result = diagnose(problem, solve(problem))
    assert not result.success
    d = result.posture["diagnosis"]
    assert d["summary"] == result.diagnosis and "\n" not in result.diagnosis
    return result, d


def test_target_out_of_reach_names_the_task_and_its_distance():
    result, d = _diagnose(_problem({"tasks.0.target": [1.5, -0.35, 0.9]}))
    assert result.diagnosis.startswith("target of task 0 is ")
    assert "beyond reach of gripper_right_base_link" in result.diagnosis
    (cause,) = d["causes"]
    assert cause["kind"] == "task" and cause["unit"] == "m"
    # the demo's target (0.45, -0.35, 0.9) is reached: the gap is at most the way back to it,
    # and the arm of Talos does not reach 0.3 m further than that
    assert 0.3 < cause["amount"] < 1.05


def test_millimetre_target_is_named_as_such():
    with pytest.warns(ImplausibleValueWarning, match="millimetres"):
        result, d = _diagnose(_problem({"tasks.0.target": [450, -350, 900]}))
    assert "beyond reach of gripper_right_base_link" in result.diagnosis
    assert "millimetres?" in result.diagnosis
    assert d["causes"][0]["amount"] > 1000


def test_torque_limit_names_the_joint_and_the_excess_is_enough():
    data = _problem({"tasks.0.target": [0.6, -0.3, 1.3], "options.torque_limit_scale": 0.1})
    result, d = _diagnose(data)
    assert result.diagnosis.startswith("torque limit of arm_right_")
    torque = [c for c in d["causes"] if c["kind"] == "torque"]
    assert torque and {c["kind"] for c in d["causes"]} == {"torque"}
    # with every limit raised by the largest excess (and 5 %), a posture is found
    worst = max(c["amount"] for c in torque)
    data["options"]["torque_limit_scale"] = 0.1 * (1 + worst / 100) * 1.05
    assert solve(problem_from_dict(data)).success


def test_contact_out_of_reach_names_the_contact():
    contact = {"robot_patch": "left_hand", "surface": "wall", "type": "fixed", "position": [0, 0]}
    data = _problem({})
    data["surfaces"].append(WALL)
    data["contacts"].append(contact)
    with pytest.warns(ImplausibleValueWarning, match="farther than gripper_right_base_link"):
        result, d = _diagnose(data)
    assert result.diagnosis.startswith(
        "contact 'left_hand' cannot reach its pose on surface 'wall' ("
    )
    (cause,) = [c for c in d["causes"] if c["kind"] == "contact"]
    assert cause["subject"] == "left_hand" and 0.5 < cause["amount"] < 3.0


def test_floating_contact_out_of_reach_is_far_from_its_plane():
    data = _problem({})
    data["surfaces"].append(WALL)
    data["contacts"].append({"robot_patch": "left_hand", "surface": "wall", "type": "support"})
    result, _ = _diagnose(data)
    assert result.diagnosis.startswith("contact 'left_hand' cannot reach surface 'wall' (")
    assert "m from its plane" in result.diagnosis


def test_friction_names_the_coefficient_that_would_do():
    data = _problem({"mu": 0.1, "surfaces.0.rpy": [0.0, 0.4, 0.0]})
    result, d = _diagnose(data)
    assert result.diagnosis.startswith("friction at contact '")
    need = max(c["amount"] for c in d["causes"] if c["kind"] == "friction")
    assert 0.1 < need < 2.0
    data["mu"] = need * 1.05
    assert solve(problem_from_dict(data)).success


def test_collision_with_an_obstacle_only():
    """The left foot is fixed inside a box: only a collision blocks it (not the contact)."""
    data = _problem(
        {"obstacles": [{"name": "block", "box": [0.4, 0.25, 0.2], "position": [0.0, 0.1, 0.15]}]}
    )
    result, d = _diagnose(data)
    assert {c["kind"] for c in d["causes"]} == {"collision"}
    assert "would have to overlap obstacle 'block' by" in result.diagnosis
    assert "leg_left_" in result.diagnosis


def test_self_collision_only():
    """Both grippers at one point: they reach it, but their proxies would overlap."""
    frames = ("gripper_left_base_link", "gripper_right_base_link")
    data = _problem({"options.self_collision": True})
    data["tasks"] = [{"type": "position", "frame": f, "target": [0.4, 0.0, 1.0]} for f in frames]
    result, d = _diagnose(data)
    assert {c["kind"] for c in d["causes"]} == {"collision"}
    assert "arm_left_7_link and arm_right_7_link would have to overlap each other" in (
        result.diagnosis
    )


def test_a_feasible_problem_is_said_feasible():
    """IPOPT stopped by max_iter: the relaxed program meets every row."""
    problem = problem_from_dict(_problem({"options.solver": {"max_iter": 3}}))
    found = from_relaxed(relax(problem))
    assert found.feasible and found.causes == ()
    assert found.line.startswith("no constraint blocks it")


def test_diagnose_returns_the_posture_a_feasible_relaxed_program_found():
    """The same problem through diagnose: solved again from the relaxed posture (3 iterations
    are not enough), so the relaxed posture itself, which passes every check; its notes say
    so and the file verifies."""
    problem = problem_from_dict(_problem({"options.solver": {"max_iter": 3}}))
    first = solve(problem)
    assert not first.success
    result = diagnose(problem, first)
    assert result.success and result.verification.ok
    assert any("relaxed program" in n for n in result.posture["notes"])
    assert result.posture["diagnosis"] is None


def test_diagnosis_leaves_the_problem_as_it_was():
    problem = problem_from_dict(_problem({"tasks.0.target": [1.5, -0.35, 0.9]}))
    key = problem.key()
    first = solve(problem)
    diagnosed = diagnose(problem, first)
    assert problem.elastic is None and problem.key() == key
    assert first.diagnosis == "" and first.posture["diagnosis"] is None
    np.testing.assert_array_equal(first.q, diagnosed.q)
    assert diagnosed.diagnosis


def test_rejected_posture_names_the_failed_checks():
    report = VerifyReport(
        (Check("tasks", 0.0, 1e-6), Check("contact geometry", 3.14, 1e-6, "patch turned"))
    )
    d = from_rejection(report)
    assert isinstance(d, Diagnosis)
    assert d.line == "IPOPT's posture fails the re-check: contact geometry 3.14 > 1e-06 " + (
        "(patch turned)"
    )


@settings(max_examples=60, deadline=None)
@given(
    ft=st.tuples(*[st.floats(-3.0, 3.0, allow_nan=False)] * 2),
    fn=st.floats(-1.0, 3.0),
    faces=st.integers(3, 12),
    cone=st.booleans(),
    grip=st.sampled_from([0.0, 0.5, 2.0]),
)
def test_required_mu_is_the_least_that_holds_the_force(ft, fn, faces, cone, grip):
    """With a grip, the cone holds the force pressed by it (ψ = f + grip·n, the forces' rows)."""
    assume(fn + grip >= 0.05)  # else a pull beyond the grip: no μ holds it (checked below)
    model = FrictionModel("cone") if cone else FrictionModel("pyramid", faces)
    psi = np.array([*ft, fn + grip])
    mu = required_mu(np.array([*ft, fn]), model, grip)
    assert np.array(model.constraints(ca.DM(psi), mu)).max() <= 1e-9 * (1 + mu)  # holds at mu
    if mu > 1e-6:  # and not below it
        assert np.array(model.constraints(ca.DM(psi), 0.99 * mu)).max() > 0
    assert required_mu(np.array([*ft, -grip - 0.1]), model, grip) == np.inf


def test_categories_of_the_blocks():
    assert category("task0.gripper_right_base_link.position") == "task"
    assert category("torque_limits") == "torque"
    assert category("contact.left_sole.position") == "contact"
    assert category("contact.left_sole.friction") == "friction"
    assert category("collision.self") == "collision"
    assert category("equilibrium.force") is None and category("equilibrium.moment") is None


def test_elastic_program_derivatives_with_collision_rows():
    """The hand-built collision derivatives extended to their slacks, against CasADi's and
    central differences, at seeded random x and multipliers."""
    data = _problem({"options.self_collision": True})
    data["obstacles"] = [{"name": "box", "box": [0.3, 0.3, 0.3], "position": [0.5, 0.15, 0.9]}]
    problem = problem_from_dict(data)
    active = ActiveSet.of(problem)  # rows: the self pairs near at q_init, 4 spheres per box
    self_pairs = tuple(sorted(active.scan(problem.q_init, 0.002).near_self))
    env_pairs = tuple((int(i), 0) for i in np.flatnonzero(active.allowed[:, 0])[:4])
    assert self_pairs and env_pairs
    term = CollisionTerm(active.pm, self_pairs, env_pairs, active.boxes, 0.002)
    relaxed = Program.of(dataclasses.replace(problem, elastic=Elastic()), collision_term=term)
    prog = symbolic(relaxed)
    assert {"slack.collision.self", "slack.collision.env", "slack.torque_limits"} <= set(
        prog.x_index
    )
    assert not any(n.startswith("slack.equilibrium") for n in prog.x_index)
    jac_g, hess_lag = prog.derivative_functions["jac_g"], prog.derivative_functions["hess_lag"]
    x, f, g = prog.x, prog.f, prog.g
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
    auto = ca.Function(
        "auto",
        [x, prog.p, lam_f, lam_g],
        [ca.jacobian(g, x), ca.hessian(lam_f * f + ca.dot(lam_g, g), x)[0]],
    )
    compiled = relaxed.compile()
    x0, p, _, _ = relaxed.numeric(compiled)
    rng = np.random.default_rng(3)
    for _ in range(2):
        xv = x0 + 0.05 * rng.normal(size=x0.size)
        lam = rng.normal(size=compiled.n_g)
        J_auto, H_auto = (np.array(v) for v in auto(xv, p, 0.7, lam))
        J = np.array(jac_g(xv, p)[1])
        upper = np.array(hess_lag(xv, p, 0.7, lam))
        H = upper + np.triu(upper, 1).T
        np.testing.assert_allclose(J, J_auto, atol=1e-9 * np.abs(J_auto).max())
        np.testing.assert_allclose(H, H_auto, atol=1e-9 * np.abs(H_auto).max())
        h = 1e-6
        J_fd = np.array(
            [
                (
                    np.array(compiled.nlp(xv + h * e, p)[1])
                    - np.array(compiled.nlp(xv - h * e, p)[1])
                ).ravel()
                / (2 * h)
                for e in np.eye(xv.size)
            ]
        ).T
        np.testing.assert_allclose(J, J_fd, atol=1e-6 * max(1.0, np.abs(J).max()))


def test_cli_prints_the_diagnosis_as_one_line_on_stderr(tmp_path, capsys):
    problem = tmp_path / "far.yaml"
    problem.write_text(yaml.safe_dump(_problem({"tasks.0.target": [1.5, -0.35, 0.9]})))
    assert main(["solve", str(problem), "--out", str(tmp_path / "out")]) == 1
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("posturegen: no posture: target of task 0 is")
    assert out.strip().splitlines() == [f"wrote {tmp_path / 'out' / 'posture.json'}"]
    posture = json.loads((tmp_path / "out" / "posture.json").read_text())
    assert posture["success"] is False
    assert posture["diagnosis"]["summary"] in lines[0]


def test_climb_stage_failure_is_diagnosed(tmp_path):
    from posturegen.climb.sequence import run_sequence

    stage = {k: STAND[k] for k in ("contacts", "tasks")}
    far = copy.deepcopy(stage)
    far["tasks"][0]["target"] = [1.5, -0.35, 0.9]
    seq = {
        "robot": "talos",
        "surfaces": STAND["surfaces"],
        "options": {"initial": "half_sitting"},
        "stages": [{"name": "reach", **stage}, {"name": "too far", **far}],
    }
    report = run_sequence(seq, tmp_path)
    assert [s.result.success for s in report.stages] == [True, False]
    last = report.stages[-1]
    assert last.diagnosis.startswith("target of task 0 is")
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert index["stages"][-1]["diagnosis"] == last.diagnosis
    posture = json.loads((tmp_path / last.posture_file).read_text())
    assert posture["diagnosis"]["summary"] == last.diagnosis
