"""The proxies' disk cache holds what it keys on: the fitting code, the URDF, the SRDF and the
collision meshes' files (an edited mesh is fitted anew, a file the robot does not read is not)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from posturegen.collision.proxies import _cache_key, mesh_files
from posturegen.model.robot import Robot, load_robot, shipped_models_dir

# a binary STL's triangle after its 80-byte header and count: normal, 3 vertices, attribute
_TRIANGLE = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def _hrp2(root: Path) -> Robot:
    return load_robot({"urdf": str(root / "hrp2.urdf"), "srdf": str(root / "hrp2.srdf")})


def _shift_stl(path: Path, dx: float) -> None:
    """Move a binary STL's vertices by ``dx`` [m] along x."""
    raw = path.read_bytes()
    n = int(np.frombuffer(raw[80:84], "<u4")[0])
    tri = np.frombuffer(raw[84 : 84 + _TRIANGLE.itemsize * n], _TRIANGLE).copy()
    tri["v"][:, :, 0] += dx
    path.write_bytes(raw[:84] + tri.tobytes())


def test_an_edited_collision_mesh_changes_the_proxies_cache_key(tmp_path):
    root = tmp_path / "hrp2"
    shutil.copytree(shipped_models_dir() / "hrp2", root)
    key = _cache_key(_hrp2(root))
    assert _cache_key(_hrp2(root)) == key  # the same files: the cached proxies are reused
    (root / "LICENSE").write_text("a file the robot does not read")
    assert _cache_key(_hrp2(root)) == key
    body = root / "meshes" / "BODY.stl"
    _shift_stl(body, 0.001)
    robot = _hrp2(root)
    assert body in mesh_files(robot.collision_model())
    assert _cache_key(robot) != key
