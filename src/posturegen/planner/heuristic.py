"""The order of the search: a focal search (A*ε, Pearl and Kim 1982) with a bound ``FOCAL``.

Cost of a transition [m]: ``STEP_COST``, plus ``AWAY`` × the rise of the distance-to-goal h
it causes (a move that takes the goal farther away), plus ``RECENT_COST`` for removing a
contact placed fewer than ``RECENT`` transitions before (re-placing what was just placed).
Every transition costs at least ``STEP_COST``, so :meth:`Heuristic.bound` (``STEP_COST`` ×
the transitions the goal still needs at least: an add per goal contact not held, and a remove
first when its patch is in contact elsewhere) never exceeds the cost left: it is admissible,
and consistent (a transition changes it by at most one step). The search takes, among the
transitions whose ``g + bound`` is within ``FOCAL`` × the least of the open list, the one of
least :meth:`Heuristic.f` (g + W·(h + penalty): the informed but inadmissible distance), ties
to fewer stages; so the path found costs at most ``FOCAL`` times the cheapest among the
transitions that verify.

h [m] sums, over the goal's contacts, the distance from the patch to its goal surface (0 once
the stance holds the contact), or for a frame goal the frame's distance to its point; plus
GUIDE × the distance of every other patch to its goal spot, in contact or not (this orders
the surfaces a hand may take, and taking a hand off does not bring the goal nearer). The
penalty counts the contacts a stance lacks (CONTACT_PENALTY [m] each, below 3 with hands, 2
without)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .goal import Goal
from .layout import Region
from .node import Key

W = 2.0  # weight of h in the focal order
FOCAL = 3.0  # bound on the path's cost against the cheapest (A*ε's 1 + ε)
STEP_COST = 0.05  # [m] per transition
AWAY = 1.0  # [m of cost per m] charged for a rise of h
RECENT = 3  # a contact removed within this many transitions of its placing...
RECENT_COST = 0.05  # [m] ...costs this much more
GUIDE = 0.2  # weight of a non-goal patch's distance to its goal spot
CONTACT_PENALTY = 0.05  # [m] per contact below the comfortable count


@dataclass(frozen=True)
class Heuristic:
    """h, the admissible bound and the focal order of stances for one goal."""

    goal: Goal
    areas: Mapping[str, Region]
    spots: Mapping[str, np.ndarray]
    comfortable: int

    def h(self, key: Key, positions: Mapping[str, np.ndarray], frame: np.ndarray | None) -> float:
        """Distance-to-goal [m] of a stance whose patches are at ``positions``; ``frame``: the
        goal frame's position (3,) [m] (frame goals); 0 once the goal is reached."""
        if self.reached(key, frame):
            return 0.0
        on = dict(key)
        total = 0.0
        goal_patches = {p for p, _ in self.goal.contacts}
        for p, s in self.goal.contacts:
            if on.get(p) != s:
                total += self.areas[s].distance(positions[p])
        if self.goal.point is not None and frame is not None:
            total += float(np.linalg.norm(frame - np.array(self.goal.point)))
        for p, spot in self.spots.items():
            if p not in goal_patches and p in positions:
                total += GUIDE * float(np.linalg.norm(positions[p] - spot))
        return total

    def bound(self, key: Key) -> float:
        """A lower bound [m] on the cost left: STEP_COST per transition the goal contacts
        still need (an add each, a remove before it when the patch is elsewhere); one for a
        frame goal."""
        on = dict(key)
        if not self.goal.contacts:  # a frame goal: one posture more may reach it
            return STEP_COST
        steps = sum(1 + (p in on) for p, s in self.goal.contacts if on.get(p) != s)
        return STEP_COST * steps

    def cost(self, h_from: float, h_to: float, recent: bool) -> float:
        """A transition's cost [m]: STEP_COST, AWAY × the rise of h, RECENT_COST for
        removing a contact placed within RECENT transitions."""
        return STEP_COST + AWAY * max(0.0, h_to - h_from) + (RECENT_COST if recent else 0.0)

    def penalty(self, key: Key) -> float:
        """CONTACT_PENALTY per contact below the comfortable count."""
        return CONTACT_PENALTY * max(0, self.comfortable - len(key))

    def f(self, g: float, h: float, key: Key) -> float:
        """The focal order (lowest first)."""
        return g + W * (h + self.penalty(key))

    def reached(self, key: Key, frame: np.ndarray | None) -> bool:
        """The stance holds every goal contact, or the frame is within the tolerance."""
        if self.goal.contacts:
            return set(self.goal.contacts) <= set(key)
        if frame is None or self.goal.point is None:
            return False
        return float(np.linalg.norm(frame - np.array(self.goal.point))) <= self.goal.tolerance
