"""Search nodes: a stance (each robot patch in contact on a surface, its contact fixed where
it was realized) with the posture that holds it, and the transition that led there."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..problem import Problem
from ..solve import Result

Key = frozenset[tuple[str, str]]  # (robot patch, surface) of every contact of a stance


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
