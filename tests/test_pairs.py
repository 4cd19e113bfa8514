"""The pair rule and the certificate: no posture is verified while a link pair outside the
four reasons (adjacent, srdf, reference_overlap, user) intersects on the meshes, and a hand
edit of a posture file (its exclusions, its gravity) cannot turn it into a verified one."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from posturegen import problem_from_dict, solve
from posturegen.collision.pairs import pair_rule, reference_configuration
from posturegen.model.robot import load_bundled
from posturegen.verify import verify_file, verify_posture
from tests.conftest import brute_force_intersections, colliding_pairs, hits_in

# the case: Talos, both feet fixed near half-sitting, a deep squat to a right-gripper
# target; without self-collision avoidance its thighs go into each other and into the pelvis
SQUAT: dict[str, Any] = {
    "robot": "talos",
    "mu": 0.7,
    "surfaces": [{"name": "ground", "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]}],
    "contacts": [
        {"robot_patch": "left_sole", "surface": "ground", "type": "fixed", "position": [0, 0.081]},
        {
            "robot_patch": "right_sole",
            "surface": "ground",
            "type": "fixed",
            "position": [0, -0.081],
        },
    ],
    "tasks": [
        {"type": "position", "frame": "gripper_right_base_link", "target": [0.115, 0.051, 0.603]}
    ],
    "options": {"initial": "half_sitting", "self_collision": True},
}


@pytest.fixture(scope="module")
def squat_without_avoidance():
    data = copy.deepcopy(SQUAT)
    data["options"]["self_collision"] = False
    result = solve(problem_from_dict(data))
    assert result.success, result.message
    return result


def _as_checked(result) -> dict[str, Any]:
    """The posture of a solve without self-collision avoidance, with the self check on (the
    unchecked list a solve with it would write: none of the user's)."""
    posture = copy.deepcopy(result.posture)
    with_rows = problem_from_dict(SQUAT)
    from posturegen.io.posture_file import _collision_dict

    posture["collision"] = _collision_dict(with_rows, None)
    return posture


def test_the_squat_without_avoidance_intersects_and_is_rejected(squat_without_avoidance, talos):
    posture = _as_checked(squat_without_avoidance)
    hits = brute_force_intersections(posture)
    assert any(h.startswith("leg_") for h in hits), hits  # into the thigh
    report = verify_posture(posture, talos.model, talos.collision_model())
    check = {c.name: c for c in report.checks}["collision: self (meshes)"]
    assert not report.ok and check.value > 0.001  # the deepest pair, in metres
    assert check.detail.startswith(hits_in(check.detail, hits)) and "mm" in check.detail


@pytest.mark.parametrize("margin", [0.0, 0.01])
def test_the_squat_with_avoidance_is_never_verified_with_intersections(margin):
    """The squat with every pair avoided: with the proxies merely apart (margin 0) it is
    verified, and the brute-force check finds no intersection; with the default 1 cm margin
    the thighs cannot get that far apart (no posture found), and whatever is found is
    verified only without intersections."""
    data = copy.deepcopy(SQUAT)
    data["options"]["collision_margin"] = margin
    data["options"]["solver"] = {"max_iter": 1000}
    result = solve(problem_from_dict(data))
    if margin == 0.0:
        assert result.success, result.message
    if result.success:
        assert brute_force_intersections(result.posture) == []
        assert result.posture["checks"]["collision: self (meshes)"]["value"] == 0


def test_a_hand_edited_exclusion_list_does_not_verify_a_colliding_posture(
    squat_without_avoidance, talos, tmp_path: Path
):
    """Marking the intersecting pairs as srdf or reference_overlap pairs changes nothing
    (verify recomputes those reasons); the old ``exclude`` list is not read; marking them as
    the user's is honoured, but verify's output names each and says it intersects."""
    posture = _as_checked(squat_without_avoidance)
    model = talos.model
    hits = brute_force_intersections(posture)
    geometry = talos.collision_model()
    joints = set()
    for hit in hits:
        a, b = (geometry.geometryObjects[geometry.getGeometryId(n)] for n in hit.split("/"))
        joints.add(tuple(sorted((model.names[a.parentJoint], model.names[b.parentJoint]))))
    assert joints, "the squat without avoidance must intersect somewhere"
    for reason in ("srdf", "reference_overlap", "adjacent"):
        edited = copy.deepcopy(posture)
        edited["collision"]["unchecked"] += [{"pair": list(p), "reason": reason} for p in joints]
        edited["collision"]["exclude"] = [list(p) for p in joints]
        path = tmp_path / f"{reason}.json"
        path.write_text(json.dumps(edited))
        assert not verify_file(path).ok, reason
    edited = copy.deepcopy(posture)
    edited["collision"]["unchecked"] += [{"pair": list(p), "reason": "user"} for p in joints]
    path = tmp_path / "user.json"
    path.write_text(json.dumps(edited))
    report = verify_file(path)
    text = report.summary()
    for a, b in joints:
        assert f"{a}/{b} (intersecting" in text or f"{b}/{a} (intersecting" in text
    assert "NOT checked at the user's request" in text


@pytest.mark.parametrize("gravity", [[0.0, 0.0, -1.62], [0.0, 0.0, 9.81], [0, 0, 0], "down"])
def test_a_posture_file_whose_gravity_was_edited_is_rejected(gravity, tmp_path: Path):
    import yaml

    from posturegen.cli import _demo_dir

    data = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
    result = solve(problem_from_dict(data))
    assert result.success, result.message
    path = result.write(tmp_path / "posture.json")
    assert verify_file(path).ok
    posture = json.loads(path.read_text())
    posture["gravity"] = gravity
    path.write_text(json.dumps(posture))
    report = verify_file(path)
    assert not report.ok
    names = {c.name for c in report.failures}
    assert names & {"static equilibrium", "gravity"}


@pytest.mark.parametrize("name", ["talos", "hrp2", "atlas", "g1", "romeo"])
def test_the_pair_rule_has_the_four_reasons_and_checks_every_other_pair(name):
    """Every unchecked pair has one of the rule's reasons, recomputed here: adjacent joints,
    SRDF-disabled (all their geometry pairs), or meshes overlapping at the reference."""
    robot = load_bundled(name)
    model, geometry = robot.model, robot.collision_model()
    srdf = str(robot.srdf) if robot.srdf else None
    rule = pair_rule(model, geometry, srdf)
    q_ref = reference_configuration(model, srdf)
    if "half_sitting" in robot.reference_configurations:
        np.testing.assert_array_equal(q_ref, robot.reference_configurations["half_sitting"])
    else:
        np.testing.assert_array_equal(q_ref, pin.neutral(model))
    parent = [int(o.parentJoint) for o in geometry.geometryObjects]
    every = [(i, j) for i in range(len(parent)) for j in range(i + 1, len(parent))]
    overlapping = {
        tuple(sorted((parent[i], parent[j])))
        for i, j in colliding_pairs(model, geometry, q_ref, every)
    }
    for (a, b), reason in rule.unchecked.items():
        adjacent = a == b or model.parents[a] == b or model.parents[b] == a
        if reason == "adjacent":
            assert adjacent
        elif reason == "srdf":
            mine = [(i, j) for i, j in every if tuple(sorted((parent[i], parent[j]))) == (a, b)]
            assert all(p in rule.srdf_disabled for p in mine)
        else:
            assert reason == "reference_overlap" and (a, b) in overlapping
    checked = {
        tuple(sorted((parent[i], parent[j]))) for i, j in rule.checked_geometry_pairs(geometry)
    }
    assert checked.isdisjoint(rule.unchecked)
    assert checked | set(rule.unchecked) == {
        tuple(sorted((parent[i], parent[j]))) for i, j in every
    }
