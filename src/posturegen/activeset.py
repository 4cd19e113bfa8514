"""The active set of collision avoidance: which candidate pairs a problem has, how far apart
they are at a posture, and which of them enter the program's rows.

Candidates: the proxy model's self pairs (:func:`posturegen.collision.proxy_model`) without
the user's exclusions (when the problem avoids self-collisions), and every sphere against every
environment box it must keep off (:func:`posturegen.collision.env_boxes`; the links in contact
with a surface may touch the solid under it). A self pair enters the rows when it is closer than
margin + ``activation``, a sphere-box pair when closer than margin + ``environment_activation``
(:class:`posturegen.collision.CollisionOptions`); :func:`posturegen.solve.solve` adds the
violated ones after each IPOPT run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from .collision import EnvBox, ProxyModel, box_distances, env_boxes, excluded_joint_ids, proxy_model
from .kinematics import scratch_data

Pairs = set[tuple[int, int]]


@dataclass
class CollisionCheck:
    """A problem's candidate pairs: ``cand_self`` (k, 2) sphere pairs (``cand_index`` into
    ``pm.self_pairs``) and the (sphere, box) pairs where ``avoid`` (S, B) is True."""

    problem: Any  # posturegen.problem.Problem with collision_options
    pm: ProxyModel
    boxes: list[EnvBox]
    cand_index: np.ndarray
    cand_self: np.ndarray
    avoid: np.ndarray

    @classmethod
    def of(cls, problem: Any) -> CollisionCheck:
        """The candidates of ``problem`` (its collision options must be set)."""
        opts = problem.collision_options
        pm = proxy_model(problem.robot)
        boxes = env_boxes(problem)
        excluded = excluded_joint_ids(problem.robot, opts) if opts.self_collision else None
        cand_index, cand_self = self_candidates(pm, excluded)
        avoid = np.zeros((len(pm.spheres), len(boxes)), dtype=bool)
        for k, box in enumerate(boxes):
            avoid[:, k] = ~np.isin(pm.joint_ids, sorted(box.allowed_joints))
        return cls(problem, pm, boxes, cand_index, cand_self, avoid)

    def distances(self, q: np.ndarray, within: float) -> tuple[np.ndarray, np.ndarray]:
        """Candidate self distances (k,) and sphere-box distances (S, B) [m] at q (nq,); +inf
        for self pairs that cannot be closer than ``within`` (their broad phase) and for the
        boxes a sphere may touch."""
        model = self.problem.robot.model
        data = scratch_data(model)
        pin.forwardKinematics(model, data, q)
        centers = self.pm.centers_world(model, data)
        d_env = np.zeros((len(centers), 0))
        if self.boxes:
            d_env = box_distances(self.pm, centers, self.boxes)
        d_self = np.zeros(0)
        if len(self.cand_self):
            d_self = self.pm.self_distances_within(centers, within, self.cand_index)
        return d_self, np.where(self.avoid, d_env, np.inf)

    def below(
        self, dist: tuple[np.ndarray, np.ndarray], self_bound: float, env_bound: float
    ) -> tuple[Pairs, Pairs]:
        """The self pairs (sphere, sphere) and sphere-box pairs (sphere, box index) whose
        distances (:meth:`distances`) are below the bounds [m]."""
        d_self, d_env = dist
        near_self = {
            tuple(map(int, self.cand_self[k])) for k in np.flatnonzero(d_self < self_bound)
        }
        near_env = {(int(i), int(k)) for i, k in zip(*np.nonzero(d_env < env_bound), strict=True)}
        return near_self, near_env  # type: ignore[return-value]

    def entering(self, dist: tuple[np.ndarray, np.ndarray], margin: float) -> tuple[Pairs, Pairs]:
        """The pairs that enter the rows at these distances: closer than margin + activation."""
        opts = self.problem.collision_options
        return self.below(dist, margin + opts.activation, margin + opts.environment_activation)

    @property
    def n_env_candidates(self) -> int:
        """Sphere-box pairs that are avoided."""
        return int(self.avoid.sum())


def box_label(box: EnvBox) -> str:
    """An environment box as the user named it: ``obstacle 'wall'``, or ``the solid under
    surface 'ground'``."""
    if box.name.startswith("surface:"):
        return f"the solid under surface '{box.name[len('surface:') :]}'"
    return f"obstacle '{box.name}'"


# candidate self pairs per proxy model and exclusions (the model is held: its id stays its own)
_CANDIDATES: dict[
    tuple[int, frozenset[tuple[int, int]] | None], tuple[Any, np.ndarray, np.ndarray]
] = {}


def self_candidates(pm: Any, excluded: Pairs | None) -> tuple[np.ndarray, np.ndarray]:
    """Indices of pm.self_pairs whose joints are not an ``excluded`` pair (None: no self
    pairs at all), and those pairs (k, 2), cached: masking Talos' 20,528 pairs took 0.3-0.5 ms
    per solve."""
    key = (id(pm), None if excluded is None else frozenset(excluded))
    hit = _CANDIDATES.get(key)
    if hit is not None and hit[0] is pm:
        return hit[1], hit[2]
    if excluded is None:
        index = np.zeros(0, dtype=int)
    elif not excluded:
        index = np.arange(len(pm.self_pairs))
    else:
        jid = pm.joint_ids
        a, b = jid[pm.self_pairs[:, 0]], jid[pm.self_pairs[:, 1]]
        index = np.flatnonzero(
            [(min(x, y), max(x, y)) not in excluded for x, y in zip(a, b, strict=True)]
        )
    if len(_CANDIDATES) > 64:
        _CANDIDATES.clear()
    _CANDIDATES[key] = (pm, index, pm.self_pairs[index])
    return _CANDIDATES[key][1], _CANDIDATES[key][2]
