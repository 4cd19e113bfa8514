"""A plan's goal: a set of contacts to reach, or a point that a robot frame must reach.

Two formats (YAML or a dict)::

    contacts:                                 # reached when the stance holds all of them
      - {robot_patch: left_sole, surface: step4}
      - {robot_patch: right_sole, surface: step4}

    frame: base_link                          # reached when |p_frame - point| <= tolerance
    point: [0.9, 0.0, 1.3]                    # [m], world
    tolerance: 0.05                           # [m], default 0.05
    weight: 0.3                               # soft task pulling the frame there, default 0.3
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _fields as F
from ..errors import InputError
from ..hints import with_hint

DEFAULT_TOLERANCE = 0.05  # [m]
DEFAULT_FRAME_WEIGHT = 0.3  # weight of the soft task weight·|p - point|²/(0.1 m)²


@dataclass(frozen=True)
class Goal:
    """``contacts``: (robot patch, surface) pairs the last stance must hold; or ``frame`` at
    ``point`` (3,) [m] within ``tolerance`` [m]."""

    contacts: tuple[tuple[str, str], ...] = ()
    frame: str | None = None
    point: tuple[float, float, float] | None = None
    tolerance: float = DEFAULT_TOLERANCE
    weight: float = DEFAULT_FRAME_WEIGHT

    def describe(self) -> str:
        """One line: what the plan must reach."""
        if self.contacts:
            return ", ".join(f"{p} on {s}" for p, s in self.contacts)
        x, y, z = self.point or (0.0, 0.0, 0.0)
        return f"{self.frame} within {self.tolerance:.3g} m of ({x:.3g}, {y:.3g}, {z:.3g})"

    def to_dict(self) -> dict[str, Any]:
        """The goal in its input format."""
        if self.contacts:
            return {"contacts": [{"robot_patch": p, "surface": s} for p, s in self.contacts]}
        return {
            "frame": self.frame,
            "point": list(self.point or ()),
            "tolerance": self.tolerance,
            "weight": self.weight,
        }


def _known(name: str, known: Iterable[str], field: str, what: str) -> str:
    known = list(known)
    if name not in known:
        raise InputError(
            field,
            f"unknown {what} '{name}'",
            with_hint(name, known, f"use one of: {', '.join(known)}"),
        )
    return name


def parse_goal(
    value: Any, patches: Iterable[str], surfaces: Iterable[str], frames: Iterable[str]
) -> Goal:
    """A Goal from its dict, each name checked against the robot's patches and frames and the
    scene's surfaces."""
    patches, surfaces = list(patches), list(surfaces)
    goal = F.require_mapping(value, "goal")
    if "contacts" in goal:
        F.check_keys(goal, "goal", ["contacts"], [])
        items = goal["contacts"]
        if not isinstance(items, list) or not items:
            raise InputError(
                "goal.contacts", "expected a non-empty list", "write [{robot_patch, surface}]"
            )
        pairs: list[tuple[str, str]] = []
        for i, c in enumerate(items):
            fld = f"goal.contacts[{i}]"
            c = F.require_mapping(c, fld)
            F.check_keys(c, fld, ["robot_patch", "surface"], [])
            p = _known(
                F.string(c["robot_patch"], f"{fld}.robot_patch"),
                patches,
                f"{fld}.robot_patch",
                "robot patch",
            )
            s = _known(
                F.string(c["surface"], f"{fld}.surface"), surfaces, f"{fld}.surface", "surface"
            )
            if p in (q for q, _ in pairs):
                raise InputError(
                    f"{fld}.robot_patch", f"'{p}' is listed twice", "give one surface per patch"
                )
            pairs.append((p, s))
        return Goal(contacts=tuple(pairs))
    if "frame" not in goal:
        raise InputError(
            "goal",
            "neither contacts nor frame",
            "give contacts: [...] or frame: NAME, point: [x, y, z]",
        )
    F.check_keys(goal, "goal", ["frame", "point"], ["tolerance", "weight"])
    frame = F.string(goal["frame"], "goal.frame")
    known_frames = list(frames)
    if frame not in known_frames:
        raise InputError(
            "goal.frame",
            f"unknown frame '{frame}'",
            with_hint(frame, known_frames, "name a frame of the robot"),
        )
    point = F.vector(goal["point"], 3, "goal.point")
    tol = F.number(goal.get("tolerance", DEFAULT_TOLERANCE), "goal.tolerance", positive=True)
    weight = F.number(goal.get("weight", DEFAULT_FRAME_WEIGHT), "goal.weight", minimum=0.0)
    x, y, z = (float(v) for v in point)
    return Goal(frame=frame, point=(x, y, z), tolerance=tol, weight=weight)


def goal_point(goal: Goal) -> np.ndarray | None:
    """The frame goal's point (3,) [m], None for a contacts goal."""
    return None if goal.point is None else np.array(goal.point)
