"""A fixed contact ``unloaded``: the patch kept exactly where it is, bearing nothing (the
planner's removals), re-checked by verify."""

from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from posturegen import problem_from_dict, solve
from posturegen.errors import InputError
from posturegen.verify import verify_posture
from tests.stances import talos_on_ground

STAND = talos_on_ground(self_collision=True)
STAND["contacts"][0]["unloaded"] = True


def test_an_unloaded_sole_stays_where_it_is_and_bears_nothing():
    problem = problem_from_dict(STAND)
    result = solve(problem)
    assert result.success, result.message
    left, right = result.posture["contacts"]
    assert left["unloaded"] and left["forces"] == [] and result.forces["left_sole"] == ()
    model = problem.robot.model
    weight = pin.computeTotalMass(model) * np.linalg.norm(model.gravity.linear)  # [N]
    total = sum(f.force for f in result.forces["right_sole"])  # the right sole bears it all
    assert total[2] == pytest.approx(weight, rel=1e-6)
    assert verify_posture(result.posture, model).ok
    moved = copy.deepcopy(result.posture)
    moved["contacts"][0]["pose"]["position"][0] += 0.01  # not where it is: rejected
    failed = [c.name for c in verify_posture(moved, model).checks if not c.ok]
    assert failed == ["contact geometry"], failed


def test_unloaded_is_a_boolean():
    data = copy.deepcopy(STAND)
    data["contacts"][0]["unloaded"] = "yes"
    with pytest.raises(InputError, match=r"contacts\[0\]\.unloaded: expected true or false"):
        problem_from_dict(data)


def test_loaded_and_unloaded_are_two_structures_with_their_own_rows():
    loaded = copy.deepcopy(STAND)
    loaded["contacts"][0]["unloaded"] = False
    a, b = problem_from_dict(STAND), problem_from_dict(loaded)
    assert a.key() != b.key()
    assert (
        "contact.left_sole.forces" not in a.summary() and "contact.left_sole.forces" in b.summary()
    )
    assert np.isfinite(solve(b).q).all()
