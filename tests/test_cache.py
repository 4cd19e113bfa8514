"""The package's one bounded cache (posturegen._cache): eviction, keys that hold their objects,
clear_caches, and solvers that always belong to their problem's robot."""

from __future__ import annotations

import copy
import gc

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import posturegen
from posturegen import _cache, problem_from_dict
from posturegen._cache import BoundedCache, Ref, memoize
from posturegen.cli import _demo_dir
from posturegen.model.robot import load_robot
from posturegen.solver import compile as compile_module
from tests.conftest import HRP2_URDF

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


@settings(max_examples=50, deadline=None, database=None)
@given(st.integers(1, 6), st.lists(st.integers(0, 9), max_size=40))
def test_bounded_cache_keeps_the_most_recently_used(size, keys):
    """After any sequence of look-ups and stores, the cache holds the ``size`` most recently
    used distinct keys."""
    cache: BoundedCache[int] = BoundedCache("test", size, register=False)
    used: list[int] = []
    for k in keys:
        assert cache.get_or_make(k, lambda k=k: 10 * k) == 10 * k
        used = [u for u in used if u != k] + [k]
    kept = used[-size:]
    assert len(cache) == len(kept)
    assert all(k in cache for k in kept)
    assert not any(k in cache for k in used[:-size])


def test_ref_compares_by_identity_and_holds_its_object():
    a, b = [1, 2], [1, 2]  # equal, unhashable, distinct
    assert Ref(a) == Ref(a) and Ref(a) != Ref(b)
    assert hash(Ref(a)) == id(a)
    cache: BoundedCache[str] = BoundedCache("test", 2, register=False)
    cache.put(Ref(a), "a")
    assert cache.get(Ref(a)) == "a" and cache.get(Ref(b)) is None


def test_clear_caches_empties_every_registered_cache():
    calls: list[int] = []

    @memoize("test memo", 4)
    def square(x: int) -> int:
        calls.append(x)
        return x * x

    assert square(3) == 9 and square(3) == 9 and calls == [3]
    posturegen.clear_caches()
    assert all(len(c) == 0 for c in _cache._ALL)
    assert square(3) == 9 and calls == [3, 3]


def test_a_bad_bound_is_refused():
    with pytest.raises(ValueError, match="size"):
        BoundedCache("test", 0)


def _hrp2_problem(name: str):
    data = copy.deepcopy(STAND)
    data["robot"] = {
        "urdf": str(HRP2_URDF),
        "srdf": str(HRP2_URDF.with_suffix(".srdf")),
        "patches": "hrp2",
        "name": name,
    }
    data["tasks"] = [{"type": "position", "frame": "r_gripper", "target": [0.35, -0.25, 0.75]}]
    return problem_from_dict(data)


def test_more_robots_than_the_bound_each_get_their_own_solver(monkeypatch):
    """With room for one compiled program, robots loaded one after the other (freed in
    between, so that a new model could take an old one's id) each get a solver built for
    their own model: the key holds the model, never its id alone."""
    monkeypatch.setattr(compile_module, "_CACHE", BoundedCache("test solvers", 1))
    monkeypatch.setattr(compile_module, "_PROGRAMS", BoundedCache("test programs", 1))
    for k in range(3):
        for problem in (_hrp2_problem(f"hrp2-{k}"), problem_from_dict(copy.deepcopy(STAND))):
            compiled = problem.compile()
            assert compiled.key == problem.key()
            assert compiled.key[0].obj is problem.robot.model
            joints = compiled.x_index["joints"]
            assert joints.stop - joints.start == problem.robot.nj
            del problem, compiled
            gc.collect()


def test_load_robot_never_renames_a_shared_robot():
    spec = {"urdf": str(HRP2_URDF), "srdf": str(HRP2_URDF.with_suffix(".srdf"))}
    a = load_robot({**spec, "name": "first"})
    b = load_robot({**spec, "name": "second"})
    assert (a.name, b.name) == ("first", "second")
    assert load_robot({**spec, "name": "first"}) is a
    assert load_robot(spec).name == "hrp2"


def test_the_compiler_found_follows_cc_and_path(monkeypatch, tmp_path):
    """The compiler search is cached on ($CC, $PATH): another PATH searches again."""
    from posturegen import _compiler

    fake = tmp_path / "mycc"
    fake.write_text("#!/bin/sh\nexit 0\n")
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    assert _compiler.compiler() is None  # no gcc, no cc on that PATH
    monkeypatch.setenv("CC", "mycc")
    assert _compiler.compiler() == str(fake)
    monkeypatch.setenv("PATH", str(tmp_path / "elsewhere"))
    assert _compiler.compiler() is None
