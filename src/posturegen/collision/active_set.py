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

from .._cache import BoundedCache, Ref
from ..model.kinematics import at_origin, base_to_world, scratch_data
from .boxes import CollisionOptions, EnvBox, env_boxes, excluded_joint_ids, row_box_distances
from .broad_phase import Close, closest
from .joint_maps import JointMap, activation, joint_maps
from .mesh_check import placed_intersections
from .proxies import ProxyModel, proxy_model
from .rows import CollisionTerm
from .slots import SELF_SLOT_BLOCK, Capacity, SelfFill
from .stance_hold import CAP_REACH, stance_caps

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


# the self pairs closer than a slack at a posture, per (proxy model, posture's joints, slack,
# links), for the first scan of a solve (its initial posture, the same for a planner's
# queries): the violated ones and the near ones, each at the holds without a stance's caps
_BELOW: BoundedCache[Close] = BoundedCache("self pairs below a slack", 64)
# the near self pairs held at a posture with a stance's holds (the closest of each link pair)
_NEAR: BoundedCache[frozenset[tuple[int, int]]] = BoundedCache("near self pairs", 64)


def _within(close: Close, slack: np.ndarray) -> Close:
    """The pairs of ``close`` closer than their joint pair's ``slack`` (P,) [m]."""
    return close.take(close.d < slack[close.link])


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
    near_maps: set[int] = field(default_factory=set)  # joint maps (indices into ActiveSet.maps)
    violated_maps: set[int] = field(default_factory=set)
    # every candidate joint pair whose proxies are below their violation threshold, held or
    # not: its clearance [m] (the margin, or the cap of a stance's hold)
    below: dict[tuple[int, int], float] = field(default_factory=dict)
    # a sphere-box pair or a checked joint map violated, held or not (the meshes do not
    # measure those against the margin: solve._Loop.standing)
    box_or_map_violated: bool = False

    @property
    def violated(self) -> bool:
        """Whether a pair or a joint map outside the held ones is violated."""
        return bool(self.violated_self or self.violated_env or self.violated_maps)


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
    caps: np.ndarray | float = np.inf  # (P,) [m] holds' caps (stance_hold.stance_caps)
    maps: tuple[JointMap, ...] = ()  # the robot's joint maps (collision.joint_maps)
    maps_on: set[int] = field(default_factory=set)  # those whose rows hold (checked, near)
    # [rad] how near a disc of each map the joints come before its rows hold (joint_maps)
    map_reach: tuple[float, ...] = ()
    # the slots of the rows (slots.Capacity): grows with the pairs held, never shrinks
    capacity: Capacity = field(default_factory=Capacity)
    # the sphere centres (S, 3) and the margin of the last scan (term() lets go of far pairs)
    _last: tuple[np.ndarray, float] | None = field(default=None, repr=False)

    @classmethod
    def of(cls, problem: Any) -> ActiveSet:
        """An empty active set for ``problem`` (its collision options set): its candidate
        self pairs (those the pair rule leaves checked, minus the user's exclusions and the
        pairs that fixed contacts place, see :func:`placed_pairs`; none without
        self-collision) and its boxes."""
        opts = problem.collision_options
        robot = problem.robot
        pm = proxy_model(robot)
        links = np.zeros(0, dtype=int)
        if opts.self_collision:
            links = pm.links_of(frozenset(excluded_joint_ids(robot, opts)) | placed_pairs(problem))
        model = robot.model
        reach = max(CAP_REACH, opts.largest_margin())  # every margin the loop tries
        caps = stance_caps(problem, pm, reach) if len(links) else np.inf
        maps = joint_maps(robot, pm) if opts.self_collision else ()
        reach_maps = tuple(activation(m, pm.rule.reference_q) for m in maps)
        data = scratch_data(model)
        boxes = env_boxes(problem)
        return cls(pm, links, boxes, opts, model, data, caps=caps, maps=maps, map_reach=reach_maps)

    @property
    def n_env_candidates(self) -> int:
        """Sphere-box pairs that are avoided."""
        return int(self.allowed.sum())

    def __post_init__(self) -> None:
        self.allowed = np.ones((len(self.pm.spheres), len(self.boxes)), dtype=bool)
        for k, box in enumerate(self.boxes):  # a sphere may touch the boxes of its contacts
            self.allowed[:, k] = ~np.isin(self.pm.joint_ids, sorted(box.allowed_joints))

    def scan(self, q: np.ndarray, margin: float, near: bool = True) -> Scan:
        """The violated pairs not yet held (the closest of each pair of links) at posture q,
        and the near pairs (the closest of each pair of links): always with ``near``, else
        only when a pair is violated (the loop ends at a posture without one; the near self
        pairs within 5 cm are thousands, their search was 3/4 of a scan)."""
        pin.forwardKinematics(self.model, self.data, at_origin(q))
        body = self.pm.centers_world(self.model, self.data)  # (S, 3) in the base's frame
        centers = base_to_world(q, body)  # (S, 3) world
        self._last = (centers, margin)  # where term() may let go of far pairs
        out = Scan()
        reference = self.pm.pair_clearance(margin)  # (P,) [m] the holds without the caps
        clearance = np.minimum(reference, self.caps)
        if len(self.links):
            slack = violation_threshold(clearance)
            bad = self._below(q, body, slack, violation_threshold(reference) if near else None)
            held = np.array(
                [
                    (min(a, b), max(a, b)) in self.self_pairs
                    for a, b in zip(bad.i, bad.j, strict=True)
                ],
                dtype=bool,
            )
            out.violated_self = closest(bad.take(~held), SELF_PER_LINK).tuples()
            out.below = {
                (int(self.pm.joint_pairs[k][0]), int(self.pm.joint_pairs[k][1])): float(
                    clearance[k]
                )
                for k in np.unique(bad.link)
            }
        if self.boxes:
            near = margin + self.options.environment_activation  # the largest threshold
            d_env = row_box_distances(self.pm, centers, self.boxes, near)
            d_env = np.where(self.allowed, d_env, np.inf)
            out.near_env = self._env(d_env, near)
            out.box_or_map_violated = bool(np.any(d_env < margin - TOL_VIOLATION))
            fresh = np.where(self._held_env(), np.inf, d_env)
            out.violated_env = self._env(fresh, margin - TOL_VIOLATION)
        if len(self.links) and (near or out.violated_self or out.violated_env):
            slack = clearance + self.options.activation
            wider = reference + self.options.activation if near else None
            out.near_self = self._near_self(q, body, slack, wider)
        self._scan_maps(q, near, out)
        return out

    def _scan_maps(self, q: np.ndarray, near: bool, out: Scan) -> None:
        """The checked joint maps not yet held whose discs q (nq,) is in (violated) or, with
        ``near``, within the map's reach [rad] of (joint_maps.activation); whether a checked
        map is violated, held or not."""
        if not self.maps:
            return  # (most robots: no set of the checked pairs made at every scan)
        checked = set(self.links.tolist())
        for k, m in enumerate(self.maps):
            if self.pm.link_index(*m.joints) not in checked:
                continue
            gap = m.gap(q[7:])
            out.box_or_map_violated |= gap < 0
            if k in self.maps_on:
                continue
            if gap < 0:
                out.violated_maps.add(k)
            elif near and gap < self.map_reach[k]:
                out.near_maps.add(k)

    def term(self, margin: float) -> CollisionTerm:
        """The collision rows of the pairs held now, ``margin`` [m] apart, in the slots of
        ``capacity``. Pairs that no longer fit are first let go of where they are far at the
        last posture scanned (see :meth:`_let_go`); only then is the capacity doubled."""
        held = tuple(sorted(self.self_pairs))
        if not self._fits(held):
            self._let_go()
            held = tuple(sorted(self.self_pairs))
        if not self._fits(held):
            self._trim()
            held = tuple(sorted(self.self_pairs))
        term = CollisionTerm(
            self.pm,
            held,
            tuple(sorted(self.env_pairs)),
            self.boxes,
            margin,
            self.capacity,
            self_collision=self.options.self_collision,
            maps=self.maps,
            mapped=tuple(k in self.maps_on for k in range(len(self.maps))),
        )
        self.capacity = term.capacity
        return term

    def _let_go(self) -> None:
        """Drop the held pairs that are now farther than their activation (self pairs:
        ``activation`` beyond their hold; sphere-box pairs: ``environment_activation`` beyond
        the margin) at the last posture scanned: the ones an active set gathered on its way
        and no longer needs. A solve that meets many pairs (Talos reaching into its belly,
        tightening its margin twice: 149 blocks of 16) stays in its program instead of
        compiling one twice as large."""
        if self._last is None:
            return
        centers, margin = self._last
        if self.self_pairs:
            held = np.minimum(self.pm.pair_clearance(margin), self.caps)
            ij = np.array(sorted(self.self_pairs), dtype=int)
            link = self.pm.link_indices(self.pm.joint_ids[ij[:, 0]], self.pm.joint_ids[ij[:, 1]])
            d = self.pm.distances(centers, ij[:, 0], ij[:, 1])
            keep = d < held[link] + self.options.activation
            self.self_pairs = {(int(i), int(j)) for i, j in ij[keep]}
        if self.env_pairs and self.boxes:
            near = margin + self.options.environment_activation
            d_env = row_box_distances(self.pm, centers, self.boxes, near)
            self.env_pairs = {(i, k) for i, k in self.env_pairs if d_env[i, k] < near}

    def _fits(self, held: tuple[tuple[int, int], ...]) -> bool:
        """Whether the pairs held (``held``: the self pairs, sorted) fit the capacity."""
        needs = SelfFill.of(self.pm, held).blocks
        return needs <= self.capacity.self_blocks and len(self.env_pairs) <= (
            self.capacity.env_slots
        )

    def _trim(self) -> None:
        """Keep, of each pair of links, the SELF_SLOT_BLOCK pairs closest at the last posture
        scanned (one block; the violated ones among them), and of each link and box the
        ENV_PER_LINK closest: what a round holds from scratch. A pair trimmed that a later
        posture violates comes back in the next round; only when even these do not fit does
        the capacity double."""
        if self._last is None:
            return
        centers, _margin = self._last
        if self.self_pairs:
            ij = np.array(sorted(self.self_pairs), dtype=int)
            link = self.pm.link_indices(self.pm.joint_ids[ij[:, 0]], self.pm.joint_ids[ij[:, 1]])
            d = self.pm.distances(centers, ij[:, 0], ij[:, 1])
            kept = closest(Close(ij[:, 0], ij[:, 1], link, d), SELF_SLOT_BLOCK)
            self.self_pairs = set(kept.tuples())
        if self.env_pairs and self.boxes:
            d_env = row_box_distances(self.pm, centers, self.boxes)
            pairs = sorted(self.env_pairs, key=lambda p: d_env[p])
            count: dict[tuple[int, int], int] = {}
            kept_env = set()
            for i, k in pairs:
                group = (int(self.pm.joint_ids[i]), k)
                count[group] = count.get(group, 0) + 1
                if count[group] <= ENV_PER_LINK:
                    kept_env.add((i, k))
            self.env_pairs = kept_env

    def _posture_key(self, q: np.ndarray, slack: np.ndarray) -> tuple[Any, ...]:
        """The key of a scan's result at posture q with ``slack`` (P,) [m] over this set's
        candidate links (the proxy model held): q's joints. The self pairs are searched
        among centres in the base's frame (model.kinematics.at_origin), a function of the
        joints alone bit for bit, so that a scan cached at one base pose is the one another
        computes (from world centres they differed by ~1e-15; keyed on all of q instead,
        each stance of talos-stances-collision searched its own, 8 ms a call)."""
        return (Ref(self.pm), q[7:].tobytes(), slack.tobytes(), self.links.tobytes())

    def _below(
        self, q: np.ndarray, centers: np.ndarray, slack: np.ndarray, wider: np.ndarray | None
    ) -> Close:
        """The candidate self pairs closer than ``slack`` (P,) [m] at q (centres (S, 3) in the
        base's frame). With ``wider`` (P,) >= slack (a solve's first posture): those closer
        than ``wider`` are cached per posture (the holds of its stance aside: the caps only
        lower them), and this stance's are among them."""
        if wider is None:
            return self.pm.close_pairs(centers, slack, self.links)
        return _within(self._cached_close(q, centers, wider), slack)

    def _near_self(
        self, q: np.ndarray, centers: np.ndarray, slack: np.ndarray, wider: np.ndarray | None
    ) -> set:
        """The SELF_PER_LINK closest sphere pairs of each candidate pair of links closer than
        ``slack`` (P,) [m] at q (centres (S, 3) in the base's frame), cached per posture.
        With ``wider`` (P,) >= slack (a solve's first posture, shared by every stance), from
        the cached pairs closer than it; else searched with ``slack`` (a run's solution)."""

        def make() -> frozenset[tuple[int, int]]:
            if wider is None:
                near = self.pm.closest_pairs(centers, slack, SELF_PER_LINK, self.links)
            else:
                near = closest(_within(self._cached_close(q, centers, wider), slack), SELF_PER_LINK)
            return frozenset(near.tuples())

        return set(_NEAR.get_or_make(self._posture_key(q, slack), make))

    def _cached_close(self, q: np.ndarray, centers: np.ndarray, slack: np.ndarray) -> Close:
        """The candidate self pairs closer than ``slack`` (P,) [m] at q (centres in the base's
        frame), cached on q's joints and the slack."""
        key = self._posture_key(q, slack)

        def make() -> Close:
            found = self.pm.close_pairs(centers, slack, self.links)
            for a in (found.i, found.j, found.link, found.d):
                a.flags.writeable = False  # shared by every solve from this posture
            return found

        return _BELOW.get_or_make(key, make)

    def grow(self, scan: Scan) -> None:
        """Hold the scan's near and violated pairs too."""
        self.self_pairs |= scan.near_self | scan.violated_self
        self.env_pairs |= scan.near_env | scan.violated_env
        self.maps_on |= scan.near_maps | scan.violated_maps

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


def placed_pairs(problem: Any) -> frozenset[tuple[int, int]]:
    """Joint pairs (sorted ids) that both carry a fixed contact's patch: the contacts place
    them, no variable moves one against the other, so a program row between them is a
    constant. Such a row was infeasible whenever the stance put their proxies closer than the
    margin (Talos, feet 16 cm apart at yaws 0.045 and 0.109 rad: soles' proxies 1 mm apart,
    meshes apart; 12 of 12 reaches failed after 180-440 iterations). Their meshes are still
    re-checked (posturegen.verify): a stance whose feet intersect fails there."""
    joints = sorted({c.patch.joint_id for c in problem.contacts if c.fixed_in_place})
    return frozenset((a, b) for i, a in enumerate(joints) for b in joints[i + 1 :])


def placed_blocked(problem: Any) -> str | None:
    """Why no posture of ``problem`` can pass the mesh self-collision check when its fixed
    contacts place two links' meshes into each other (each link at T_world_target·
    T_joint_patch⁻¹ of its contact), else None. Found before any IPOPT run: such a stance
    (Talos, feet yawed toward each other 15 cm apart) used to spend the call's whole budget
    tightening a margin that cannot move them."""
    opts = problem.collision_options
    if opts is None or not opts.self_collision:
        return None
    placed: dict[int, pin.SE3] = {}
    for c in problem.contacts:
        if c.fixed_in_place:  # its pose is given: T_world_target
            placed.setdefault(c.patch.joint_id, c.T_world_target * c.patch.T_joint_patch.inverse())
    robot = problem.robot
    srdf = str(robot.srdf) if robot.srdf else None
    user = frozenset(excluded_joint_ids(robot, opts))
    hits = placed_intersections(robot.model, robot.collision_model(), srdf, placed, user)
    if not hits:
        return None
    pairs = ", ".join(f"{name} {1000 * depth:.1f} mm" for depth, name in hits[:3])
    return (
        f"the fixed contacts place meshes into each other ({pairs} deep): no posture separates "
        "them; move a contact, or leave the pair unchecked (options.collision_exclude)"
    )


def box_label(box: EnvBox) -> str:
    """An environment box as the user named it: ``obstacle 'wall'``, or ``the solid under
    surface 'ground'``."""
    if box.name.startswith("surface:"):
        return f"the solid under surface '{box.name[len('surface:') :]}'"
    return f"obstacle '{box.name}'"
