"""Plans on scenes nobody scripted: a problem file's start stance and a goal file
(examples/plans/NAME.yaml, NAME.goal.yaml and, if any, NAME.rules.yaml; Talos and HRP-2),
every posture of the path verified, the goal contacts held at the end, no contact put back
where it was removed from."""

from __future__ import annotations

import json
import multiprocessing
from pathlib import Path

import pytest
import yaml

from posturegen import plan
from posturegen.io.problem_file import read_yaml
from posturegen.model.robot import load_bundled
from posturegen.planner import Budget
from posturegen.verify import verify_posture

PLANS = Path(__file__).resolve().parent.parent / "examples" / "plans"
SCENES = [
    "platform",
    "stepping_stones",
    "beam",
    "high_step",
    "rail_step",
    "hrp2_platform",
    "ladder_platform",
]


@pytest.mark.parametrize("name", SCENES)
def test_a_scene_of_our_own_is_planned_and_every_posture_verified(name, tmp_path):
    start, goal = PLANS / f"{name}.yaml", PLANS / f"{name}.goal.yaml"
    rules = PLANS / f"{name}.rules.yaml"
    report = plan(
        str(start),
        tmp_path,
        goal=str(goal),
        rules=str(rules) if rules.is_file() else None,
        budget=Budget(nodes=30),
    )
    assert report.success, report.summary.get("stop")
    robot = load_bundled(read_yaml(start)["robot"])
    index = json.loads((tmp_path / "sequence.json").read_text())
    places: list[set[tuple[str, str]]] = []
    for stage in index["stages"]:
        posture = json.loads((tmp_path / stage["posture"]).read_text())
        assert stage["success"] and verify_posture(posture, robot.model).ok, stage["name"]
        places.append(
            {(c["robot_patch"]["name"], c["surface"]["name"]) for c in posture["contacts"]}
        )
    wanted = {(c["robot_patch"], c["surface"]) for c in read_yaml(goal)["contacts"]}
    assert wanted <= places[-1]
    # a (patch, surface) left is never taken again: the path goes forward
    left: set[tuple[str, str]] = set()
    for before, after in zip(places, places[1:], strict=False):
        assert not (after - before) & left, (before, after)
        left |= before - after


def test_a_step_too_high_for_the_legs_alone_ends_with_what_blocked_it(tmp_path):
    """rail_step's step raised to 65 cm, without its rules (no hands): with one sole up there
    and the other on the ground no posture puts the weight on the upper one, and the plan ends
    unreached, naming the best stance and the unload that kept the goal. (At the scene's
    50 cm the same plan ends unreached too, but a first start moved by ~1e-16 reached it in a
    deep squat: what blocks there is the solver's path, not the body.)"""
    scene = read_yaml(PLANS / "rail_step.yaml")
    step = next(s for s in scene["surfaces"] if s["name"] == "step")
    step["position"][2] = 0.65
    start = tmp_path / "high.yaml"
    start.write_text(yaml.safe_dump(scene))
    report = plan(
        str(start),
        tmp_path / "out",
        goal=str(PLANS / "rail_step.goal.yaml"),
        budget=Budget(nodes=30),
    )
    assert not report.success
    summary = report.summary
    assert summary["stop"] == "no transition left to try"
    assert "right_hand" not in summary["best"]  # the legs alone
    assert any("unload" in line for line in summary["blocked"]), summary["blocked"]


def test_two_workers_keep_transitions_in_flight_and_verify_every_posture(tmp_path):
    """``workers=2``: transitions solved on the pool as they land; the goal reached with
    every posture verified, and no worker left running once the call returns (the
    transitions still in flight when the goal held were abandoned)."""
    start = PLANS / "platform.yaml"
    report = plan(
        str(start),
        tmp_path,
        goal=str(PLANS / "platform.goal.yaml"),
        budget=Budget(nodes=30),
        workers=2,
    )
    assert report.success, report.summary.get("stop")
    robot = load_bundled("talos")
    index = json.loads((tmp_path / "sequence.json").read_text())
    for stage in index["stages"]:
        posture = json.loads((tmp_path / stage["posture"]).read_text())
        assert stage["success"] and verify_posture(posture, robot.model).ok, stage["name"]
    assert multiprocessing.active_children() == []
