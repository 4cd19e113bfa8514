"""Search nodes: a stance (each robot patch in contact on a surface, its contact fixed where
it was realized) with the posture that holds it, and the transition that led there."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..solver.problem import Problem
from ..solver.solve import Result

Key = frozenset[tuple[str, str]]  # (robot patch, surface) of every contact of a stance
# a stance with where each contact is, to CELL: the search holds each place once
Place = frozenset[tuple[str, str, tuple[int, int, int]]]
CELL = 0.1  # [m]


def cell(p: np.ndarray) -> tuple[int, int, int]:
    """The CELL-sized cube (indices) that holds a world point (3,) [m]."""
    i, j, k = (int(v) for v in np.floor(np.asarray(p, dtype=float) / CELL))
    return i, j, k


def place_of(key: Key, positions: dict[str, np.ndarray]) -> Place:
    """A stance's place: each contact's patch, surface and the cell of the patch."""
    return frozenset((p, s, cell(positions[p])) for p, s in key)


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
        """The place after this transition (an add's patch at its target's cell)."""
        if self.kind == "add" and self.target is not None:
            return place | {(self.patch, self.surface, cell(np.array(self.target)))}
        return frozenset(x for x in place if x[0] != self.patch)


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

    @property
    def place(self) -> Place:
        """The stance with the cell of each contact."""
        return place_of(self.key, self.positions)

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
