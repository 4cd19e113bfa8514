"""Checks the plan tests share."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from posturegen.model.robot import Robot
from posturegen.planner.rules import patch_positions


def assert_exact_unloads(folder: Path, stages: list[dict[str, Any]], robot: Robot) -> None:
    """Every ``unload`` stage of a plan's ``sequence.json`` holds its patch within 1 mm of
    where the posture before it held it, bearing nothing; there is at least one."""
    unloads = [k for k, s in enumerate(stages) if s["name"].startswith("unload")]
    assert unloads
    for k in unloads:
        posture = json.loads((folder / stages[k]["posture"]).read_text())
        before = json.loads((folder / stages[k - 1]["posture"]).read_text())
        (held,) = [c for c in posture["contacts"] if c.get("unloaded")]
        assert held["forces"] == []
        patch = held["robot_patch"]["name"]
        now = patch_positions(robot, np.array(posture["q"]))[patch]
        was = patch_positions(robot, np.array(before["q"]))[patch]
        assert np.linalg.norm(now - was) <= 1e-3, (stages[k]["name"], now, was)
