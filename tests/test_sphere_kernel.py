"""The compiled sphere search (posturegen.collision.sphere_kernel) finds the pairs the numpy
search finds, in the same order and at the same distances (bit for bit), on seeded random
postures of Talos and HRP-2."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from posturegen._compiler import compiler
from posturegen.collision import proxies, sphere_kernel
from posturegen.model.robot import load_bundled

needs_cc = pytest.mark.skipif(compiler() is None, reason="no C compiler")


def _search(pm, monkeypatch, native: bool, centers, slack, links, per_link: int):
    """The pairs close_pairs (per_link 0) or closest_pairs finds, with the compiled search
    (``native``) or the numpy one."""
    with monkeypatch.context() as m:
        if not native:
            m.setattr(sphere_kernel, "available", lambda: False)
        if per_link == 0:
            return pm.close_pairs(centers, slack, links)
        return pm.closest_pairs(centers, slack, per_link, links)


def _postures(robot, seed: int, count: int):
    """``count`` random configurations within the joint limits (the base within ±1 m)."""
    model = robot.model
    lower = np.maximum(model.lowerPositionLimit, -1.0)
    upper = np.minimum(model.upperPositionLimit, 1.0)
    pin.seed(seed)  # pinocchio's randomConfiguration draws from its own generator
    return [pin.randomConfiguration(model, lower, upper) for _ in range(count)]


@needs_cc
@pytest.mark.parametrize("name", ["talos", "hrp2"])
def test_the_compiled_search_finds_the_numpy_searchs_pairs_in_its_order(name, monkeypatch):
    robot = load_bundled(name)
    pm = proxies.proxy_model(robot)
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(7)
    found = 0
    for q in _postures(robot, 7, 12):
        pin.forwardKinematics(model, data, q)
        centers = pm.centers_world(model, data)  # (S, 3)
        slack = rng.uniform(0.0, 0.08, len(pm.joint_pairs))  # (P,) [m]
        links = np.flatnonzero(rng.random(len(pm.joint_pairs)) < 0.7)
        for per_link in (0, 1, 16):
            ours = _search(pm, monkeypatch, True, centers, slack, links, per_link)
            reference = _search(pm, monkeypatch, False, centers, slack, links, per_link)
            assert len(ours.i) == len(reference.i)
            # bit for bit, distances too: a pair's distance sets its hold in the program, and a
            # last bit made IPOPT fail a stage of HRP-2's vertical ladder
            for a, b in zip(ours.fields(), reference.fields(), strict=True):
                assert np.array_equal(a, b)
            assert np.all(ours.d < slack[ours.link])
            found += len(ours.i)
    assert found > 100  # the postures bring pairs within the slack: the comparison has content


@needs_cc
def test_the_compiled_search_is_built_once_into_the_disk_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    sphere_kernel._library.cache_clear()
    try:
        assert sphere_kernel.available()
        built = sphere_kernel._library_path()
        assert built.parent == tmp_path / "kernels" and built.exists()
        stamp = built.stat().st_mtime_ns
        sphere_kernel._library.cache_clear()
        assert sphere_kernel.available() and built.stat().st_mtime_ns == stamp  # loaded, kept
    finally:
        sphere_kernel._library.cache_clear()
