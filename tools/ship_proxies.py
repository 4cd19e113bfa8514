"""Fit (or take from the cache) the proxies of every bundled robot and write them into the
package (``src/posturegen/data/proxies``), with their joint maps (``data/joint_maps``,
posturegen.collision.joint_maps), so that no user and no CI run fits a robot we ship.

Run it from the project's root after a change of the fitting code (``collision/proxy_fit.py``,
``surface.py``, ``pairs.py``), of a bundled robot's URDF, SRDF or meshes, or of the
example-robot-data version; ``tests/test_shipped_proxies.py`` fails until it is run.
Old files (keys no bundled robot has any more) are removed."""

from __future__ import annotations

from posturegen.collision.joint_maps import joint_maps, maps_key, shipped_maps_dir, write_maps
from posturegen.collision.pairs import pair_rule
from posturegen.collision.proxies import (
    _cache_key,
    proxy_model,
    robot_spheres,
    shipped_dir,
    write_shipped,
)
from posturegen.model.robot import BUNDLED, load_bundled


def main() -> None:
    keep, keep_maps = set(), set()
    for name in BUNDLED:
        robot = load_bundled(name)
        rule = pair_rule(robot.model, robot.collision_model(), str(robot.srdf or "") or None)
        key = _cache_key(robot)
        spheres, report = robot_spheres(robot, rule, key)
        path = write_shipped(key, spheres, report)
        keep.add(path.name)
        print(f"{name}: {len(spheres)} spheres -> {path} ({path.stat().st_size / 1e3:.0f} kB)")
        pm = proxy_model(robot)
        maps = joint_maps(robot, pm)
        path = write_maps(shipped_maps_dir() / f"{maps_key(pm)}.npz", maps)
        keep_maps.add(path.name)
        print(f"{name}: {len(maps)} joint maps, {sum(len(m.discs) for m in maps)} discs -> {path}")
    for folder, kept in ((shipped_dir(), keep), (shipped_maps_dir(), keep_maps)):
        for old in folder.glob("*.npz"):
            if old.name not in kept:
                old.unlink()
                print(f"removed {old}")


if __name__ == "__main__":
    main()
