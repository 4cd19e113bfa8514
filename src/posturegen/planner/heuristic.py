"""The order of the search: f = g + W·(h + penalty).

g counts transitions (STEP_COST [m] each). h [m] sums, over the goal's contacts, the distance
from the patch to its goal surface (0 once the stance holds the contact), or for a frame goal
the frame's distance to its point; plus GUIDE × the distance of every other patch in contact
to its goal spot (this orders the surfaces a hand may take). The penalty counts the contacts
a stance lacks (CONTACT_PENALTY [m] each, below 3 with hands, 2 without)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .goal import Goal
from .layout import Region
from .node import Key

W = 2.0  # weight of h (weighted A*: W > 1 trades optimality for fewer nodes)
STEP_COST = 0.05  # [m] per transition
GUIDE = 0.2  # weight of a non-goal patch's distance to its goal spot
CONTACT_PENALTY = 0.05  # [m] per contact below the comfortable count


@dataclass(frozen=True)
class Heuristic:
    """h and f of stances for one goal."""

    goal: Goal
    areas: Mapping[str, Region]
    spots: Mapping[str, np.ndarray]
    comfortable: int

    def h(self, key: Key, positions: Mapping[str, np.ndarray], frame: np.ndarray | None) -> float:
        """Distance-to-goal [m] of a stance whose patches are at ``positions``; ``frame``: the
        goal frame's position (3,) [m] (frame goals)."""
        on = dict(key)
        total = 0.0
        goal_patches = {p for p, _ in self.goal.contacts}
        for p, s in self.goal.contacts:
            if on.get(p) != s:
                total += self.areas[s].distance(positions[p])
        if self.goal.point is not None and frame is not None:
            total += float(np.linalg.norm(frame - np.array(self.goal.point)))
        for p in on:
            if p not in goal_patches and p in self.spots:
                total += GUIDE * float(np.linalg.norm(positions[p] - self.spots[p]))
        return total

    def penalty(self, key: Key) -> float:
        """CONTACT_PENALTY per contact below the comfortable count."""
        return CONTACT_PENALTY * max(0, self.comfortable - len(key))

    def f(self, g: float, h: float, key: Key) -> float:
        """The search's priority (lowest first)."""
        return g + W * (h + self.penalty(key))

    def reached(self, key: Key, frame: np.ndarray | None) -> bool:
        """The stance holds every goal contact, or the frame is within the tolerance."""
        if self.goal.contacts:
            return set(self.goal.contacts) <= set(key)
        if frame is None or self.goal.point is None:
            return False
        return float(np.linalg.norm(frame - np.array(self.goal.point))) <= self.goal.tolerance
