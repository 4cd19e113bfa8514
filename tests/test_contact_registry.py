"""The contact types' registry (posturegen.terms.contacts): the problem file's reader, the
schema and verify loop over it; a type no registered class knows is never verified."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import ClassVar

import pytest

from posturegen import problem_from_dict, solve
from posturegen.errors import InputError
from posturegen.io.schema import problem_schema
from posturegen.terms.contacts import FixedContact, contact_types, register_contact
from posturegen.verify import verify_posture
from tests.stances import talos_on_ground

STAND = talos_on_ground()


def test_the_registry_holds_the_five_types_and_the_schema_follows_it():
    types = contact_types()
    assert set(types) == {"fixed", "geometric", "support", "inclusive", "point"}
    assert [k for k, c in types.items() if c.fixed_in_place] == ["fixed"]
    items = problem_schema()["properties"]["contacts"]["items"]["oneOf"]
    assert [i["properties"]["type"]["const"] for i in items] == list(types)
    for item in items:  # each type's own keys, and no other
        kind = item["properties"]["type"]["const"]
        own = set(item["properties"]) - {"type", "robot_patch", "surface", "name"}
        assert own == set(types[kind].keys)


def test_a_type_of_your_own_brings_its_keys_schemas(monkeypatch):
    """A registered type's keys carry their value's JSON Schema: a user's new key is in the
    problem file's schema as the type declares it (no table elsewhere to extend)."""
    from posturegen.terms.contacts import base

    pad = {"type": "number", "minimum": 0, "description": "pad thickness [m]"}

    @dataclass
    class Padded(FixedContact):
        kind: ClassVar[str] = "padded"
        keys: ClassVar = {**FixedContact.keys, "pad": pad}

    monkeypatch.setitem(base._CONTACTS._by_kind, "padded", Padded)
    items = problem_schema()["properties"]["contacts"]["items"]["oneOf"]
    (mine,) = [i for i in items if i["properties"]["type"]["const"] == "padded"]
    assert mine["properties"]["pad"] == pad
    assert mine["properties"]["yaw"] == FixedContact.keys["yaw"]


def test_a_key_of_another_type_is_named_as_such():
    data = copy.deepcopy(STAND)
    data["contacts"][1]["points"] = 6  # a support contact's key
    with pytest.raises(InputError, match=r"contacts\[1\]\.points: unknown key"):
        problem_from_dict(data)


def test_another_class_under_a_known_type_is_an_error():
    with pytest.raises(InputError, match="'fixed' is registered already"):

        @register_contact
        @dataclass
        class Mine(FixedContact):
            kind: ClassVar[str] = "fixed"


def test_verify_rejects_a_contact_type_no_class_knows():
    problem = problem_from_dict(STAND)
    result = solve(problem)
    assert result.success and verify_posture(result.posture, problem.robot.model).ok
    posture = copy.deepcopy(result.posture)
    posture["contacts"][0]["type"] = "glued"
    report = verify_posture(posture, problem.robot.model)
    assert [c.name for c in report.checks if not c.ok] == ["contact points inside polygons"]
