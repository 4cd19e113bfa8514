"""The bundled robots' proxies ship in the package: a fresh clone, with an empty cache,
fits none of them (``tools/ship_proxies.py`` writes them)."""

from __future__ import annotations

import numpy as np
import pytest

from posturegen.collision import proxies
from posturegen.collision.proxies import _cache_key, proxy_model, read_shipped, shipped_dir
from posturegen.errors import PosturegenError
from posturegen.model.robot import BUNDLED, load_bundled


@pytest.mark.parametrize("name", BUNDLED)
def test_a_bundled_robot_fits_nothing_with_an_empty_cache(name, tmp_path, monkeypatch):
    """Its proxies come from the package; a fit would raise."""

    def no_fit(*args, **kwargs):
        raise PosturegenError(f"{name} was fitted: run python tools/ship_proxies.py")

    monkeypatch.setattr(proxies, "fit_robot", no_fit)
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    robot = load_bundled(name)
    robot._proxy_model = None
    model = proxy_model(robot)
    shipped, _ = read_shipped(_cache_key(robot))
    assert len(model.spheres) == len(shipped) > 100
    assert all(s.joint_id in range(1, robot.model.njoints) for s in model.spheres)
    assert min(s.radius for s in model.spheres) >= 0  # a vertex of a box: radius 0
    assert not list((tmp_path / "proxies").glob("*.json"))  # nothing fitted nor written


def test_shipped_files_are_exactly_the_bundled_robots():
    """No stale file is shipped beside the current ones."""
    keys = {_cache_key(load_bundled(name)) for name in BUNDLED}
    assert {p.stem for p in shipped_dir().glob("*.npz")} == keys


def test_shipped_proxies_equal_the_disk_format(tmp_path):
    """A written file reads back sphere for sphere."""
    spheres, report = read_shipped(_cache_key(load_bundled("atlas")))
    monkey_dir = tmp_path / "p"
    original = proxies.shipped_dir
    try:
        proxies.shipped_dir = lambda: monkey_dir
        proxies.write_shipped("k", spheres, report)
        again, report_again = read_shipped("k")
    finally:
        proxies.shipped_dir = original
    assert report_again == report
    assert [s.joint_id for s in again] == [s.joint_id for s in spheres]
    np.testing.assert_array_equal([s.center for s in again], [s.center for s in spheres])
    np.testing.assert_array_equal([s.radius for s in again], [s.radius for s in spheres])
