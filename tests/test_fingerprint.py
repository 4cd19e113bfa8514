"""A structure's fingerprint: exact encodings of values, the same for the same structure in
any process, another for anything its declaration reads; none for code outside the package."""

from __future__ import annotations

import copy
import dataclasses
import hashlib

import numpy as np
import pinocchio as pin
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen import problem_from_dict
from posturegen.cli import _demo_dir
from posturegen.collision.proxies import proxy_model
from posturegen.collision.rows import CollisionTerm
from posturegen.collision.slots import Capacity
from posturegen.model.geometry import ConvexPolygon
from posturegen.solver.fingerprint import NotEncodable, encode, structure_fingerprint
from posturegen.solver.problem import Program
from posturegen.terms.costs import TorqueCost

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


def _digest(value: object) -> str:
    h = hashlib.sha256()
    encode(value, h)
    return h.hexdigest()


_leaves = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=False),
    st.text(max_size=6),
    st.lists(st.floats(allow_nan=False, width=64), max_size=4).map(np.array),
)
_values = st.recursive(
    _leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.lists(inner, max_size=4).map(tuple),
        st.dictionaries(st.text(max_size=4), inner, max_size=3),
    ),
    max_leaves=12,
)


def _same(a: object, b: object) -> bool:
    """Equal values of the same types all the way down (an array by dtype, shape, bits)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float):
        return a.hex() == b.hex()
    return a == b


@settings(max_examples=300, deadline=None)
@given(_values, _values)
def test_encoding_is_exact(a, b):
    """Two values get one digest iff they are the same values of the same types."""
    assert _digest(a) == _digest(copy.deepcopy(a))
    assert (_digest(a) == _digest(b)) == _same(a, b)


def test_arrays_are_encoded_whole_not_by_their_repr():
    a = np.zeros(2000)
    b = a.copy()
    b[1000] = 1e-300  # repr() of both elides the middle
    assert repr(a) == repr(b) and _digest(a) != _digest(b)
    assert _digest(np.zeros(3)) != _digest(np.zeros(3, dtype=np.float32))
    assert _digest(np.zeros((2, 3))) != _digest(np.zeros((3, 2)))


def test_a_value_without_an_exact_encoding_is_refused():
    with pytest.raises(NotEncodable):
        _digest((1, object()))
    with pytest.raises(NotEncodable):
        _digest(np.array([object()]))


def _problem(**changes):
    data = copy.deepcopy(STAND)
    data.update(changes)
    return problem_from_dict(data)


def _fingerprint(problem) -> str | None:
    return structure_fingerprint(Program.of(problem))


def test_same_structure_same_fingerprint_other_structure_another():
    base = _fingerprint(_problem())
    assert base is not None and len(base) == 32
    moved = copy.deepcopy(STAND)
    moved["tasks"][0]["target"] = [0.35, -0.45, 1.0]  # a parameter: the same structure
    assert _fingerprint(problem_from_dict(moved)) == base
    assert _fingerprint(_problem(costs={"torques": 1e-3})) != base  # one more cost term


def test_a_contact_fingerprint_reads_its_patch_geometry():
    """Two patches of one name but another polygon declare other constants."""
    problem = _problem()
    base = _fingerprint(problem)
    contact = problem.contacts[0]
    vertices = contact.patch.polygon.vertices * 0.9
    patch = dataclasses.replace(contact.patch, polygon=ConvexPolygon(vertices))
    problem.contacts[0] = dataclasses.replace(contact, patch=patch)
    assert problem.contacts[0].key() == contact.key()  # the in-process key names it only
    assert _fingerprint(problem) != base


def test_the_robot_model_is_in_the_fingerprint():
    problem = _problem()
    base = _fingerprint(problem)
    model = pin.Model(problem.robot.model)  # a copy: another object, the same content
    robot = copy.copy(problem.robot)
    robot.model = model
    problem.robot = robot
    assert _fingerprint(problem) == base
    model.effortLimit[10] *= 2.0
    robot2 = copy.copy(problem.robot)
    robot2.model = pin.Model(model)
    problem.robot = robot2
    assert _fingerprint(problem) != base


def test_collision_rows_fingerprint_their_links_rows_and_chains():
    """The collision program's structure is its capacity; which links its slots pick from,
    its rows' pairs of limbs and the links' chains are the proxy model's: a model whose limbs
    differ gives the same key and another fingerprint."""
    problem = _problem()
    pm = proxy_model(problem.robot)
    term = CollisionTerm(pm, (), (), [], 0.005, Capacity(16, 0))
    other = copy.copy(pm)
    other.limb = None  # every joint its own limb: a row per pair of links
    moved = CollisionTerm(other, (), (), [], 0.005, Capacity(16, 0))
    assert term.key() == moved.key()
    assert _digest(term.fingerprint()) != _digest(moved.fingerprint())


class OwnTorqueCost(TorqueCost):
    """A term defined outside posturegen: its code is not in the sources' digest."""


def test_a_term_defined_outside_the_package_has_no_fingerprint():
    problem = _problem()
    problem.costs.append(OwnTorqueCost(weight=1e-3))
    assert _fingerprint(problem) is None
