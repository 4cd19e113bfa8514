"""Search nodes: a stance (each robot patch in contact on a surface, its contact fixed where
it was realized) with the posture that holds it, and the transition that led there."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..solver.problem import Problem
from ..solver.solve import Result

Key = frozenset[tuple[str, str]]  # (robot patch, surface) of every contact of a stance
Cell = tuple[int, int, int]
# a stance with where each contact is, to CELL, and where each patch taken off it left (its
# surface marked FREE): the search holds each place once
Place = frozenset[tuple[str, str, Cell]]
CELL = 0.1  # [m]
# a free patch's entry in a place: (patch, FREE + the surface it left, the cell it left). One
# foot on step 2 with the other lifted from the ground is not the place of the same foot with
# the other lifted from step 1: from there the next step is another problem (ATLAS' 2-step
# stairs: the touch of step 2 from the ground spent its 1500 iterations; from step 1 it was
# never tried while the places were the same, and the plan ended without the goal)
FREE = "~"


def cell(p: np.ndarray) -> tuple[int, int, int]:
    """The CELL-sized cube (indices) that holds a world point (3,) [m]."""
    i, j, k = (int(v) for v in np.floor(np.asarray(p, dtype=float) / CELL))
    return i, j, k


def place_of(
    key: Key, positions: dict[str, np.ndarray], left: Mapping[str, tuple[str, Cell]]
) -> Place:
    """A stance's place: each contact's patch, surface and the cell of the patch, and each
    patch in ``left`` (taken off a surface: (surface, cell) it left) marked FREE."""
    contacts = {(p, s, cell(positions[p])) for p, s in key}
    return frozenset(contacts | {(p, FREE + s, c) for p, (s, c) in left.items()})


@dataclass(frozen=True)
class Action:
    """A transition: ``add`` the patch on the surface (guided to ``target`` (3,) [m]) or
    ``remove`` it from the surface it is on."""

    kind: str  # "add" | "remove"
    patch: str
    surface: str
    target: tuple[float, float, float] | None = None

    def label(self) -> str:
        """``right_sole on step1`` / ``right_sole off ground``."""
        return f"{self.patch} {'on' if self.kind == 'add' else 'off'} {self.surface}"

    def child_key(self, key: Key) -> Key:
        """The stance after this transition."""
        pair = (self.patch, self.surface)
        return key | {pair} if self.kind == "add" else key - {pair}

    def child_place(self, place: Place) -> Place:
        """The place after this transition (an add's patch at its target's cell; a removed
        patch marked FREE where it left)."""
        others = frozenset(x for x in place if x[0] != self.patch)
        if self.kind == "add" and self.target is not None:
            return others | {(self.patch, self.surface, cell(np.array(self.target)))}
        was = [c for p, s, c in place if p == self.patch and s == self.surface]
        return others | {(self.patch, FREE + self.surface, c) for c in was}

    def child_left(
        self, left: Mapping[str, tuple[str, Cell]], positions: Mapping[str, np.ndarray]
    ) -> dict[str, tuple[str, Cell]]:
        """The free patches' last contacts after this transition from a stance whose
        patches are at ``positions`` (3,) [m]."""
        out = {p: v for p, v in left.items() if p != self.patch}
        if self.kind == "remove":
            out[self.patch] = (self.surface, cell(positions[self.patch]))
        return out


@dataclass(frozen=True)
class Stage:
    """One verified posture of a transition (``touch``, ``hold`` or ``unload``)."""

    name: str
    data: dict[str, Any]  # its problem file's content
    problem: Problem
    result: Result


@dataclass
class Node:
    """A stance held by ``stages[-1]``'s posture; ``contacts`` maps each patch in contact to
    its contact's name in that problem."""

    key: Key
    contacts: dict[str, str]
    stages: tuple[Stage, ...]
    positions: dict[str, np.ndarray]  # every patch's origin at the posture, world (3,) [m]
    g: float = 0.0
    h: float = 0.0
    parent: Node | None = None
    action: Action | None = None
    depth: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
    # each patch taken off a surface on the path and not placed since: (surface, cell) it left
    left: dict[str, tuple[str, Cell]] = field(default_factory=dict)

    @property
    def place(self) -> Place:
        """The stance with the cell of each contact and where each free patch left."""
        return place_of(self.key, self.positions, self.left)

    @property
    def last(self) -> Stage:
        """The stage whose posture holds the stance."""
        return self.stages[-1]

    @property
    def q(self) -> np.ndarray:
        """The posture (nq,) holding the stance."""
        return self.last.result.q

    def path(self) -> list[Node]:
        """The nodes from the start to this one."""
        out: list[Node] = []
        node: Node | None = self
        while node is not None:
            out.append(node)
            node = node.parent
        return out[::-1]

    def describe(self) -> str:
        """``left_sole@ground, right_sole@step1``."""
        return ", ".join(f"{p}@{s}" for p, s in sorted(self.key))
