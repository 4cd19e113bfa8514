"""Contact sequences and shipped scenes: keep = fixed at the realized pose, verified stages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from posturegen.climb import parts, scenes
from posturegen.climb.sequence import run_sequence, stage_problem_dict
from posturegen.errors import ImplausibleValueWarning, InputError
from posturegen.io.problem_file import problem_from_dict
from posturegen.model.robot import load_robot, shipped_models_dir
from posturegen.verify import verify_file
from tests.conftest import brute_force_intersections


def _two_stage() -> dict:
    seq = scenes.stand_reach("talos")
    seq["options"] = {"self_collision": False, "environment_collision": False}
    frame = seq["stages"][0]["tasks"][0]["frame"]
    seq["stages"][0]["contacts"][1] = {
        "robot_patch": "right_sole",
        "surface": "ground",
        "type": "support",
        "min_radii": [0.03, 0.03],
    }
    seq["stages"].append(
        {
            "name": "reach again",
            "contacts": scenes._keep("left_sole", "right_sole"),
            "tasks": [{"type": "position", "frame": frame, "target": [0.35, -0.3, 0.8]}],
        }
    )
    return seq


def test_keep_freezes_the_contact_where_the_previous_stage_put_it(tmp_path: Path) -> None:
    seq = _two_stage()
    report = run_sequence(seq, tmp_path)
    assert report.success, [s.result.message for s in report.stages]
    first = report.stages[0].result
    # the realized pose of the floating right sole, from the first posture
    problem0 = problem_from_dict(stage_problem_dict(seq, seq["stages"][0], 0, None, None))
    floating = {c.name: c for c in problem0.contacts}["right_sole"]
    position, yaw = floating.realized_pose(problem0.robot.model, first.q)
    data = stage_problem_dict(seq, seq["stages"][1], 1, problem0, first.q)
    kept = {c["robot_patch"]: c for c in data["contacts"]}["right_sole"]
    assert kept["type"] == "fixed"
    np.testing.assert_allclose(kept["position"], position, atol=1e-12)
    assert kept["yaw"] == pytest.approx(yaw, abs=1e-12)
    # the second stage starts from the first posture, and its sole is still there
    np.testing.assert_allclose(data["options"]["initial"], first.q)
    second = report.stages[1].result
    patch_pts = [f["point"] for c in second.posture["contacts"] for f in c["forces"]]
    assert len(patch_pts) > 0
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert index["success"] and [s["name"] for s in index["stages"]] == ["reach", "reach again"]
    for s in index["stages"]:
        assert verify_file(tmp_path / s["posture"]).ok
        assert (tmp_path / s["problem"]).is_file()


def test_keep_keeps_the_friction_coefficient_of_the_contact() -> None:
    """A contact given its own μ (a hand closed on a rung) keeps it once frozen."""
    seq = _two_stage()
    seq["stages"][0]["contacts"][1]["mu"] = 1.0  # right sole; the scene's μ differs
    assert seq["mu"] != 1.0
    data0 = stage_problem_dict(seq, seq["stages"][0], 0, None, None)
    problem0 = problem_from_dict(data0)
    data = stage_problem_dict(seq, seq["stages"][1], 1, problem0, problem0.q_init)
    kept = {c["robot_patch"]: c for c in data["contacts"]}
    assert kept["right_sole"]["mu"] == 1.0
    assert kept["left_sole"]["mu"] == {c.name: c for c in problem0.contacts}["left_sole"].mu
    assert problem_from_dict(data).contacts[1].mu == 1.0


def test_a_failed_stage_ends_the_sequence_and_says_so(tmp_path: Path) -> None:
    seq = _two_stage()
    seq["stages"][1]["tasks"][0]["target"] = [2.5, -0.3, 0.8]  # out of reach
    seq["options"]["solver"] = {"max_iter": 60}
    seq["stages"].append({"name": "never", "contacts": scenes._keep("left_sole")})
    with pytest.warns(ImplausibleValueWarning, match=r"tasks\[0\]\.target: .* farther than"):
        report = run_sequence(seq, tmp_path)
    assert not report.success
    assert len(report.stages) == 2 and not report.stages[1].result.success
    assert "beyond reach of wrist_right_ft_tool_link" in report.stages[1].diagnosis
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert index["success"] is False and index["planned_stages"] == 3
    assert index["stages"][1]["success"] is False


def test_keep_in_the_first_stage_is_an_input_error() -> None:
    seq = scenes.stand_reach("talos")
    seq["stages"][0]["contacts"] = scenes._keep("left_sole")
    with pytest.raises(InputError, match="keep"):
        stage_problem_dict(seq, seq["stages"][0], 0, None, None)


def test_stairs_on_talos_maximizes_the_ellipse_against_the_riser(tmp_path: Path) -> None:
    """One step of the stairs: the foot on a step shorter than itself, stopped by the next
    step's block (its riser), verified on the meshes by coal."""
    seq = scenes.stairs("talos", steps=1)
    report = run_sequence(seq, tmp_path)
    assert report.success, [s.result.message for s in report.stages]
    posture = json.loads((tmp_path / report.stages[-1].posture_file).read_text())
    assert any(name.startswith("collision") for name in posture["checks"])
    contact = {c["name"]: c for c in posture["contacts"]}["right_sole"]
    radii = contact["ellipse"]["radii"]
    step_depth = scenes.robot_size("talos").sole_length * 0.65
    # the ellipse is as deep as the step allows, much more than the 2 cm minimum
    assert 2 * min(radii) > 0.25 * step_depth
    assert verify_file(tmp_path / report.stages[-1].posture_file).ok


def test_paper_robots_are_shipped_and_named(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """HRP-2 and ATLAS load by name from any working directory (the package ships them)."""
    monkeypatch.chdir(tmp_path)
    for name in ("hrp2", "atlas"):
        assert scenes.robot_spec(name) == name
        robot = load_robot(name)
        assert robot.urdf.is_file() and robot.urdf.is_relative_to(shipped_models_dir())
        assert len(robot.collision_model().geometryObjects) > 0
        assert robot.model.nv == 36
    with pytest.raises(InputError, match="unknown robot"):
        scenes.robot_spec("asimo")


def test_vertical_ladder_stages_follow_the_paper() -> None:
    """Paper V-B, as built for HRP-2: both hands on the first rung at or above the shoulders
    before the right foot leaves the ground, the right foot guided (a soft task) towards the
    middle of rung 1, then the left foot on rung 2 as a geometric contact whose ellipse spans
    the rung's thickness and most of the foot's width, the right foot and both hands kept."""
    seq = scenes.ladder_vertical("hrp2")
    size = scenes.robot_size("hrp2")
    names = [s["name"] for s in seq["stages"]]
    assert names == [
        "stand",
        "right hand on rung 5",
        "left hand on rung 5",
        "right foot on rung 1",
        "left foot on rung 2",
    ]
    rungs = {s["name"]: s for s in seq["surfaces"] if s["name"].startswith("rung")}
    assert rungs["rung5"]["position"][2] >= size.shoulder_height > rungs["rung4"]["position"][2]
    foot = seq["stages"][3]
    assert [c["type"] for c in foot["contacts"]] == ["keep", "keep", "keep", "support"]
    (task,) = foot["tasks"]
    assert task["weight"] > 0 and task["target"][1] == pytest.approx(0.0)
    last = seq["stages"][-1]["contacts"]
    assert [c["name"] for c in last[:3]] == ["right_sole", "right_hand", "left_hand"]
    assert last[3]["type"] == "geometric" and last[3]["surface"] == "rung2"
    thin, wide = last[3]["min_radii"]
    assert 2 * thin >= 0.5 * scenes.RUNG_THICKNESS and 2 * wide >= 0.75 * size.sole_width
    assert seq["friction"] == {"model": "pyramid", "faces": 8}
    # a climb: before each foot climbs two rungs, the hands go five rungs above the other foot
    climb = scenes.ladder_vertical("hrp2", steps=1)["stages"]
    assert [s["name"] for s in climb[5:]] == [
        "right hand on rung 7",
        "left hand on rung 7",
        "right foot on rung 3",
        "right hand on rung 8",
        "left hand on rung 8",
        "left foot on rung 4",
    ]
    # every foot after the first is guided to its own side of the middle, on its rung
    for stage, side, rung in ((seq["stages"][4], 1, 2), (climb[7], -1, 3), (climb[10], 1, 4)):
        (task,) = stage["tasks"]
        assert task["target"][1] == pytest.approx(side * scenes.CLIMB_FOOT_Y)
        assert task["target"][2] == pytest.approx(rung * scenes.RUNG_SPACING)


def test_inclined_ladder_lifts_the_left_foot_before_placing_it() -> None:
    seq = scenes.ladder_inclined("talos")
    names = [s["name"] for s in seq["stages"]]
    assert names[-2:] == ["left foot lifted", "left foot on step 2"]
    lifted = seq["stages"][-2]
    assert [c["type"] for c in lifted["contacts"]] == ["keep", "keep"]
    (task,) = lifted["tasks"]
    step2, step3 = (next(s for s in seq["surfaces"] if s["name"] == n) for n in ("step2", "step3"))
    # level with step 2, the toes behind step 3's front edge
    toes = task["target"][0] + 0.5 * scenes.robot_size("talos").sole_length
    assert toes < step3["position"][0] - 0.06
    assert task["target"][2] == pytest.approx(step2["position"][2])


# every shipped scene on its default robot and on Talos (issue 5's CI run); those listed in
# VERIFIED must give a verified posture at every stage, the others must never write a false one
SCENE_RUNS = sorted(
    {(name, info.robot) for name, info in scenes.SCENES.items()}
    | {(name, "talos") for name in scenes.SCENES}
    | {("stand-reach", robot) for robot in parts.ROBOT_NAMES}
)
VERIFIED = {
    *(("stand-reach", robot) for robot in parts.ROBOT_NAMES),
    ("wall-brace", "talos"),
    ("stairs", "talos"),
    ("stairs", "atlas"),
    ("ladder-inclined", "hrp2"),
    ("ladder-inclined", "talos"),
    ("ladder-vertical", "hrp2"),
}


@pytest.mark.parametrize(("name", "robot"), SCENE_RUNS)
def test_scene_demo_writes_only_verified_postures(name: str, robot: str, tmp_path: Path) -> None:
    from posturegen.cli import main

    rc = main(["demo", name, "--robot", robot, "--out", str(tmp_path), "--quiet"])
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert rc in (0, 1)
    assert index["success"] is (rc == 0)
    for stage in index["stages"]:
        if stage["success"]:  # a stage said verified: the file must pass verify, meshes too
            assert verify_file(tmp_path / stage["posture"]).ok, stage["name"]
            posture = json.loads((tmp_path / stage["posture"]).read_text())
            assert brute_force_intersections(posture) == [], stage["name"]
    assert all(s["success"] for s in index["stages"][:-1])  # a failure ends the sequence
    if rc == 1:  # and says why, from the relaxed problems it solved
        assert index["stages"][-1]["diagnosis"]
    if (name, robot) in VERIFIED:
        assert rc == 0, index["stages"][-1]["message"]
        assert verify_file(tmp_path / "posture.json").ok


# the shipped climbs (issue 5): stairs >= 4 steps on ATLAS, the vertical ladder on HRP-2 with
# each foot four rungs above the demo's (ending on rungs 5 and 6); every stage verified
CLIMBS = [
    ("stairs", "atlas", 4, "left foot on step 4"),
    ("ladder-vertical", "hrp2", 2, "left foot on rung 6"),
]


@pytest.mark.parametrize(("name", "robot", "steps", "last"), CLIMBS)
def test_climb_verifies_every_stage(
    name: str, robot: str, steps: int, last: str, tmp_path: Path
) -> None:
    from posturegen.cli import main

    rc = main(["climb", name, "--robot", robot, "--steps", str(steps), "--out", str(tmp_path)])
    index = json.loads((tmp_path / "sequence.json").read_text())
    assert rc == 0, index["stages"][-1]["message"]
    assert len(index["stages"]) == index["planned_stages"]
    assert index["stages"][-1]["name"] == last
    for stage in index["stages"]:
        assert verify_file(tmp_path / stage["posture"]).ok, stage["name"]
        posture = json.loads((tmp_path / stage["posture"]).read_text())
        assert brute_force_intersections(posture) == [], stage["name"]


def test_the_inclined_ladder_climbs_one_step(tmp_path: Path) -> None:
    """`climb ladder-inclined` runs the demo's stages; more steps is a one-line error."""
    from posturegen.climb.scenes import scene

    assert [s["name"] for s in scene("ladder-inclined", "hrp2", 1)["stages"]][-1] == (
        "left foot on step 2"
    )
    with pytest.raises(InputError, match="--steps: the inclined ladder climbs one step"):
        scene("ladder-inclined", "hrp2", 2)


def test_climbs_and_plans_name_ipopt_unless_the_environment_names_a_solver(monkeypatch):
    """The shipped climbs and the planner's postures each start from the one before: they
    name SEQUENCE_METHOD (posturegen.solver.problem); a single-posture demo keeps the
    default (auto), and $POSTUREGEN_SOLVER or a method the scene gives wins."""
    from posturegen.planner.api import _solver_options
    from posturegen.planner.search import Budget
    from posturegen.solver.problem import DEFAULT_METHOD, SEQUENCE_METHOD

    monkeypatch.delenv("POSTUREGEN_SOLVER", raising=False)
    assert SEQUENCE_METHOD == "ipopt" != DEFAULT_METHOD
    for name in ("stairs", "ladder-inclined", "ladder-vertical"):
        assert scenes.scene(name)["options"]["solver"]["method"] == SEQUENCE_METHOD
    assert "method" not in scenes.scene("stand-reach")["options"]["solver"]
    seq = scenes.scene("stairs", "atlas", 1)
    problem = stage_problem_dict(seq, seq["stages"][0], 0, None, None)
    assert problem_from_dict(problem).solver_options.solver_method() == SEQUENCE_METHOD
    seq = {"options": {"solver": {"max_iter": 400}}}
    _solver_options(seq, Budget())
    assert seq["options"]["solver"]["method"] == SEQUENCE_METHOD
    seq = {"options": {"solver": {"method": "sqp"}}}
    _solver_options(seq, Budget())
    assert seq["options"]["solver"]["method"] == "sqp"
    monkeypatch.setenv("POSTUREGEN_SOLVER", "auto")
    assert "method" not in scenes.scene("stairs")["options"]["solver"]
    seq = {"options": {}}
    _solver_options(seq, Budget())
    assert "method" not in seq["options"]["solver"]
