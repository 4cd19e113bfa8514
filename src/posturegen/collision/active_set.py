"""The collision pairs a program holds, grown round by round
(:func:`posturegen.solver.solve.solve`).

A round looks at a posture: the candidate self pairs closer than ``activation`` beyond their
clearance, and the sphere-box pairs closer than ``environment_activation`` beyond the margin,
are *near*; those below their clearance (margin) are *violated*. Of each, the SELF_PER_LINK
closest of each pair of links (ENV_PER_LINK of each link and box) are taken: the proxies'
spheres are many and small, and a pair of links close over a whole face has thousands of
sphere pairs within reach, all about as close.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..model.kinematics import scratch_data
from .boxes import CollisionOptions, EnvBox, env_boxes, excluded_joint_ids, row_box_distances
from .proxies import ProxyModel, closest, proxy_model
from .rows import CollisionTerm

# the closest sphere pairs of each pair of links, and spheres of each link near each box, that
# enter the program in one round: proxies fitted to 1 cm put thousands of sphere pairs within
# reach of each other (Talos' legs at half-sitting: 4,000 within 6 cm). HRP-2's stand-reach
# found no posture with 4 or 8 (each round brought more pairs of its chest and body, all
# about as close), was verified with 16. Sphere-box pairs are rows of their own: 4 of each
# link and box (talos-box-collision, 40 problems: 25.1 instead of 32.7 ms median, 118
# instead of 150 rows)
SELF_PER_LINK = 16
ENV_PER_LINK = 4
TOL_VIOLATION = 1e-6  # [m] a sphere-box pair this far below the margin is violated
# [m] a self pair is violated this far below its clearance, when its proxies stay apart: the
# smooth minimum over the many sphere pairs of two links facing each other holds the closest
# few, the others dip a little below (Talos' stand-reach: 5 rounds instead of 3 at 1e-6)
SELF_SLACK = 1e-3


def violation_threshold(clearance: np.ndarray) -> np.ndarray:
    """[m] the distance below which a self pair of clearance c is violated: c - SELF_SLACK,
    but not below 0 when c > 0 (proxies that were apart stay apart), c - 1e-6 when c <= 0."""
    return np.minimum(clearance - 1e-6, np.maximum(clearance - SELF_SLACK, 0.0))


@dataclass
class Scan:
    """What one look at a posture found: pairs to add, and whether every violated pair is
    already held."""

    near_self: set[tuple[int, int]] = field(default_factory=set)
    near_env: set[tuple[int, int]] = field(default_factory=set)
    violated_self: set[tuple[int, int]] = field(default_factory=set)
    violated_env: set[tuple[int, int]] = field(default_factory=set)


@dataclass
class ActiveSet:
    """The self pairs (sphere index pairs) and sphere-box pairs (sphere, box) in the program."""

    pm: ProxyModel
    links: np.ndarray  # candidate joint pairs (indices into pm.joint_pairs); empty: none
    boxes: list[EnvBox]
    options: CollisionOptions
    model: pin.Model
    data: pin.Data
    self_pairs: set[tuple[int, int]] = field(default_factory=set)
    env_pairs: set[tuple[int, int]] = field(default_factory=set)

    @classmethod
    def of(cls, problem: Any) -> ActiveSet:
        """An empty active set for ``problem`` (its collision options set): its candidate
        self pairs (those the pair rule leaves checked, minus the user's exclusions; none
        without self-collision) and its boxes."""
        opts = problem.collision_options
        robot = problem.robot
        pm = proxy_model(robot)
        links = np.zeros(0, dtype=int)
        if opts.self_collision:
            links = pm.links_of(frozenset(excluded_joint_ids(robot, opts)))
        model = robot.model
        return cls(pm, links, env_boxes(problem), opts, model, scratch_data(model))

    @property
    def n_env_candidates(self) -> int:
        """Sphere-box pairs that are avoided."""
        return int(self.allowed.sum())

    def __post_init__(self) -> None:
        self.allowed = np.ones((len(self.pm.spheres), len(self.boxes)), dtype=bool)
        for k, box in enumerate(self.boxes):  # a sphere may touch the boxes of its contacts
            self.allowed[:, k] = ~np.isin(self.pm.joint_ids, sorted(box.allowed_joints))

    def scan(self, q: np.ndarray, margin: float) -> Scan:
        """The near pairs (the closest of each pair of links) and the violated pairs not yet
        held (the closest of each pair of links) at posture q."""
        pin.forwardKinematics(self.model, self.data, q)
        centers = self.pm.centers_world(self.model, self.data)
        out = Scan()
        if len(self.links):
            clearance = self.pm.pair_clearance(margin)
            close = self.pm.close_pairs(centers, clearance + self.options.activation, self.links)
            out.near_self = closest(close, SELF_PER_LINK).tuples()
            bad = close.take(close.d < violation_threshold(clearance[close.link]))
            held = np.array(
                [
                    (min(a, b), max(a, b)) in self.self_pairs
                    for a, b in zip(bad.i, bad.j, strict=True)
                ],
                dtype=bool,
            )
            out.violated_self = closest(bad.take(~held), SELF_PER_LINK).tuples()
        if self.boxes:
            d_env = np.where(self.allowed, row_box_distances(self.pm, centers, self.boxes), np.inf)
            out.near_env = self._env(d_env, margin + self.options.environment_activation)
            fresh = np.where(self._held_env(), np.inf, d_env)
            out.violated_env = self._env(fresh, margin - TOL_VIOLATION)
        return out

    def term(self, margin: float) -> CollisionTerm:
        """The collision rows of the pairs held now, ``margin`` [m] apart."""
        return CollisionTerm(
            self.pm,
            tuple(sorted(self.self_pairs)),
            tuple(sorted(self.env_pairs)),
            self.boxes,
            margin,
        )

    def grow(self, scan: Scan) -> None:
        """Hold the scan's near and violated pairs too."""
        self.self_pairs |= scan.near_self | scan.violated_self
        self.env_pairs |= scan.near_env | scan.violated_env

    def _held_env(self) -> np.ndarray:
        """(S, B) mask of the sphere-box pairs held."""
        out = np.zeros(self.allowed.shape, dtype=bool)
        for i, k in self.env_pairs:
            out[i, k] = True
        return out

    def _env(self, d: np.ndarray, below: float) -> set[tuple[int, int]]:
        """The sphere-box pairs with d (S, B) < ``below``, the ENV_PER_LINK closest of
        each link and box."""
        sphere, box = np.nonzero(d < below)
        if not len(sphere):
            return set()
        group = self.pm.joint_ids[sphere] * len(self.boxes) + box
        order = np.lexsort((d[sphere, box], group))
        group = group[order]
        keep = order[np.arange(len(group)) - np.searchsorted(group, group) < ENV_PER_LINK]
        return {(int(i), int(k)) for i, k in zip(sphere[keep], box[keep], strict=True)}


def box_label(box: EnvBox) -> str:
    """An environment box as the user named it: ``obstacle 'wall'``, or ``the solid under
    surface 'ground'``."""
    if box.name.startswith("surface:"):
        return f"the solid under surface '{box.name[len('surface:') :]}'"
    return f"obstacle '{box.name}'"
