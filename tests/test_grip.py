"""A contact's ``grip`` [N]: a hand closed around a rail presses it beyond its load, so it may
pull by up to grip/k at each of its k points and its friction grows with it
(posturegen.terms.forces); ``verify`` re-checks the forces against that cone."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from posturegen import solve
from posturegen.climb.scenes import RAIL_GRIP
from posturegen.climb.sequence import stage_problem_dict
from posturegen.errors import InputError
from posturegen.io.problem_file import problem_from_dict
from posturegen.model.robot import load_bundled
from posturegen.planner import plan
from posturegen.planner.rules import parse_rules
from posturegen.planner.scenes import plan_scene, scene_rules
from posturegen.planner.search import Budget
from posturegen.verify import verify_posture
from tests.plan_checks import assert_exact_unloads

DATA = Path(__file__).parent / "data" / "inclined_grip_unload.yaml"


@pytest.fixture(scope="module")
def gripped():
    """HRP-2 on the inclined ladder, left sole on step 2, both hands on the rails: the right
    sole unloaded on step 1 (where, with open hands, the plan stopped: infeasible)."""
    data = yaml.safe_load(DATA.read_text())
    result = solve(problem_from_dict(data))
    return data, result


def test_a_gripping_hand_bears_what_an_open_one_cannot(gripped):
    data, result = gripped
    assert result.success, result.message
    robot = load_bundled("hrp2")
    posture = result.posture
    assert verify_posture(posture, robot.model).ok
    hands = [c for c in posture["contacts"] if "hand" in c["name"]]
    assert [c["grip"] for c in hands] == [150.0, 150.0]
    # the same forces without the grip: outside the friction cones (the grip is used)
    opened = copy.deepcopy(posture)
    for c in opened["contacts"]:
        c.pop("grip", None)
    report = verify_posture(opened, robot.model)
    assert not report.ok
    assert {c.name for c in report.failures} >= {"friction cones"}


def test_a_pull_beyond_the_grip_fails_the_recheck(gripped):
    """A hand pulling by more than its grip per point: the re-check says so."""
    _, result = gripped
    robot = load_bundled("hrp2")
    posture = copy.deepcopy(result.posture)
    (hand,) = [c for c in posture["contacts"] if c["name"] == "right_hand"]
    k = len(hand["forces"])
    normal = np.array(hand["surface"]["placement"])[:3, 2]
    pulled = np.array(hand["forces"][0]["force"]) - (hand["grip"] / k + 10.0) * normal
    hand["forces"][0]["force"] = pulled.tolist()
    failed = {c.name for c in verify_posture(posture, robot.model).failures}
    assert "friction cones" in failed


def test_grip_is_checked_and_a_kept_contact_keeps_it(gripped):
    data, result = gripped
    bad = copy.deepcopy(data)
    bad["contacts"][0]["grip"] = -1.0
    with pytest.raises(InputError, match=r"^contacts\[0\]\.grip: "):
        problem_from_dict(bad)
    geometric = copy.deepcopy(data)
    geometric["contacts"][0] = {
        "name": "right_hand",
        "robot_patch": "right_hand",
        "surface": "right_rail",
        "type": "geometric",
        "grip": 100.0,
    }
    with pytest.raises(InputError, match=r"grip"):
        problem_from_dict(geometric)
    seq = {k: data[k] for k in ("robot", "mu", "surfaces", "obstacles")}
    stage = {"name": "kept", "contacts": [{"name": "right_hand", "type": "keep"}]}
    kept = stage_problem_dict(seq, stage, 1, problem_from_dict(data), result.q)
    assert kept["contacts"][0]["grip"] == 150.0 and kept["contacts"][0]["type"] == "fixed"


def test_the_inclined_ladder_scene_grips_its_rails_and_plans_hold_them():
    seq = plan_scene("ladder-inclined", "hrp2", None)
    robot = load_bundled("hrp2")
    rules = scene_rules("ladder-inclined", seq, robot)
    assert rules.patches["right_hand"].grip == RAIL_GRIP > 0
    assert rules.patches["left_sole"].grip == 0.0
    assert rules.to_dict()["patches"]["left_hand"]["grip"] == RAIL_GRIP
    again = parse_rules({"patches": {"left_hand": {"grip": 80.0}}}, rules)
    assert again.patches["left_hand"].grip == 80.0
    with pytest.raises(InputError, match=r"^rules\.patches\.left_hand\.grip: "):
        parse_rules({"patches": {"left_hand": {"grip": -5}}}, rules)


def test_the_inclined_ladder_is_planned_with_exact_unloads(tmp_path):
    """HRP-2, both soles to step 2, default rules (hands gripping the rails): reached, every
    posture re-checked, every removal an exact unload (the patch within 1 mm, no force)."""
    report = plan("ladder-inclined", tmp_path, robot="hrp2", budget=Budget(nodes=40))
    assert report.success and report.stats.reached
    robot = load_bundled("hrp2")
    index = json.loads((tmp_path / "sequence.json").read_text())
    stages = index["stages"]
    gripping = 0
    for stage in stages:
        posture = json.loads((tmp_path / stage["posture"]).read_text())
        assert stage["success"] and verify_posture(posture, robot.model).ok, stage["name"]
        gripping += sum(1 for c in posture["contacts"] if c.get("grip") == RAIL_GRIP)
    assert gripping > 0
    assert_exact_unloads(tmp_path, stages, robot)
