"""Collision avoidance (paper eq. 1, rows 3-4) with smooth conservative sphere proxies.

Proxies (:mod:`posturegen.collision.proxies`, fitted by :mod:`posturegen.collision.proxy_fit`):
each joint's collision geometry is covered by spheres that contain its whole surface and stand
at most 1 cm outside it; the candidate self pairs are every pair of links that the pair rule
(:mod:`posturegen.collision.pairs`) leaves checked, each held at least min(margin, its
clearance at the reference posture) apart.

Distances, as smooth CasADi expressions:

- sphere-sphere: ``|c_a - c_b| - r_a - r_b`` (smooth wherever the centres differ);
- sphere-box: the six face distances ``s_k = n_k·c - h_k`` of the box give a conservative
  distance ``max_k s_k <= dist(c, box)``; its smooth lower bound
  ``LSE_β(s) - log(6)/β <= max_k s_k`` (log-sum-exp, β = 300 /m, so at most 6 mm
  conservative) minus the radius is the distance d, and the row is d saturated at
  margin + ENV_SATURATION by a smooth minimum (still d >= margin; constant far from the box).

Self rows are one per pair of limbs (the kinematic chains between branchings): a smooth
minimum (-LSE, SOFT_MIN_BETA) of their sphere pairs' distances minus each pair's clearance,
computed in the base frame, from blocks of 16 slots, each one call of a CasADi function
(:mod:`posturegen.collision.self_blocks`). They bring their own exact Jacobian and Hessian
(through the links' twist Jacobians; tested equal to CasADi's).

Rows are kept few by an active set: of the pairs closer than ``activation`` beyond their
clearance (self pairs; ``environment_activation`` beyond the margin for sphere-box pairs) at
the current posture, the closest few of each pair of links enter the program
(:mod:`posturegen.collision.active_set`); after a solve every candidate pair is checked and
the violated ones are added before solving again (:func:`posturegen.solver.solve.solve`).

The pairs fill the slots of a :class:`Layout` (slots per joint pair, per link and box) whose
spheres are parameters: every active set that fits a layout is solved by one compiled
program, and a structure's layout grows over its solves until its problems stop building.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from .._cache import BoundedCache, Ref
from ..terms.nlp import BuildContext, Instance, Term
from .boxes import EnvBox
from .proxies import ProxyModel
from .self_blocks import SELF_SLOT_BLOCK, Block, self_block_rows
from .soft_min import ENV_SATURATION, Element, Point, box_element, center, soft_min_rows
from .stance_hold import held_clearance

# [m] a free slot's radii sum (self) or radius (env) is -DUMMY_GAP: its element of the row's
# smooth minimum is about 10 m above the others, weight exp(-β·10) = 0 exactly. Each self row
# also has a constant element, DUMMY_GAP for a row that holds pairs (weight 0: the row is
# unchanged) and FREE_ROW for a row of free slots only, which makes that row the constant
# FREE_ROW. A row that varied with q would change the solve even without a bound: IPOPT
# writes a row as g(x) - s = 0 with a slack, and its nonlinearity along a step counts as
# infeasibility (a layout with 13 more such rows: 66 iterations and another optimum, instead
# of 55)
DUMMY_GAP = 10.0
FREE_ROW = 1.0
# slots are given in blocks: SELF_SLOT_BLOCK per joint pair (the active set's SELF_PER_LINK
# closest sphere pairs, then as many violated; one call of the block's function each:
# posturegen.collision.self_blocks), ENV_SLOT_BLOCK per link and box
ENV_SLOT_BLOCK = 4


def _blocks(count: int, block: int) -> int:
    """``count`` rounded up to a multiple of ``block``."""
    return -(-count // block) * block


def _counts(a: np.ndarray, b: np.ndarray, block: int) -> tuple[tuple[int, int, int], ...]:
    """The sorted (a, b, n) of the distinct pairs of (a, b) (each (k,) ints), n their count
    rounded up to whole blocks."""
    width = int(max(a.max(initial=0), b.max(initial=0))) + 1
    keys, n = np.unique(a * width + b, return_counts=True)
    rows = zip((keys // width).tolist(), (keys % width).tolist(), n.tolist(), strict=True)
    return tuple((x, y, _blocks(c, block)) for x, y, c in rows)


@dataclass(frozen=True)
class Layout:
    """The structure of a program's collision rows, which the pairs held fill:
    ``self_slots`` (joint a, joint b, n): n sphere-pair slots of joint pair a < b;
    ``env_slots`` (joint, box, n): n sphere slots of a link and a box. The spheres are
    parameters, so two active sets that fit one layout share one compiled solver: a free
    self slot is a pair DUMMY_GAP apart, a row of free slots only is a constant without a
    bound."""

    self_slots: tuple[tuple[int, int, int], ...] = ()
    env_slots: tuple[tuple[int, int, int], ...] = ()

    @classmethod
    def needed(
        cls,
        pm: ProxyModel,
        self_pairs: tuple[tuple[int, int], ...],
        env_pairs: tuple[tuple[int, int], ...],
    ) -> Layout:
        """The smallest layout (whole blocks) that holds these sphere pairs."""
        joint = pm.joint_ids
        sp = np.array(self_pairs, dtype=int).reshape(-1, 2)
        ja, jb = joint[sp[:, 0]], joint[sp[:, 1]]
        selfs = _counts(np.minimum(ja, jb), np.maximum(ja, jb), SELF_SLOT_BLOCK)
        ep = np.array(env_pairs, dtype=int).reshape(-1, 2)
        return cls(selfs, _counts(joint[ep[:, 0]], ep[:, 1], ENV_SLOT_BLOCK))

    def union(self, other: Layout) -> Layout:
        """The layout with the slots of both (the larger count of each)."""
        out = []
        for mine, theirs in (
            (self.self_slots, other.self_slots),
            (self.env_slots, other.env_slots),
        ):
            counts: dict[tuple[int, int], int] = {}
            for a, b, n in (*mine, *theirs):
                counts[(a, b)] = max(counts.get((a, b), 0), n)
            out.append(tuple(sorted((a, b, n) for (a, b), n in counts.items())))
        return Layout(out[0], out[1])

    @property
    def size(self) -> int:
        """Slots in all."""
        return sum(n for *_, n in self.self_slots) + sum(n for *_, n in self.env_slots)


@dataclass
class CollisionTerm(Term):
    """Rows d >= margin for the active sphere pairs and sphere-box pairs (see module doc),
    laid out in the slots of ``layout`` (grown to hold them)."""

    pm: ProxyModel
    self_pairs: tuple[tuple[int, int], ...]
    env_pairs: tuple[tuple[int, int], ...]  # (sphere, box index)
    boxes: list[EnvBox]
    margin: float
    layout: Layout = field(default_factory=Layout)
    name: str = "collision"
    late: ClassVar[bool] = True  # its layout grows: declared on the program of the others

    def __post_init__(self) -> None:
        key = (Ref(self.pm), self.self_pairs, self.env_pairs, self.layout)
        fill = _FILLS.get_or_make(key, self._filled)
        self.layout, self._self_rows, self._groups, self._self_slot_pairs, self._env_rows = fill[:5]
        self._self_columns: np.ndarray = fill[5]

    def _filled(self) -> tuple[Any, ...]:
        """The layout grown to hold the pairs, its self rows, each row's sphere pairs, every
        self slot's pair and every env slot's pair (None: free), in the rows' order, and the
        self slots' parameters (read-only: shared by every term of these pairs)."""
        layout = self.layout.union(Layout.needed(self.pm, self.self_pairs, self.env_pairs))
        self_rows = _self_rows(self.pm, layout)
        fill = _self_fill(self.pm, self.self_pairs)
        groups = [
            (limb, [p for a, b, _ in slots for p in fill.get((a, b), [])])
            for limb, slots in self_rows
        ]
        slot_pairs = [
            pair
            for _, slots in self_rows
            for a, b, count in slots
            for pair in _padded(fill.get((a, b), []), count)
        ]
        env_fill = _env_fill(self.pm, self.env_pairs)
        env_rows = [
            pair
            for joint, box, count in layout.env_slots
            for pair in _padded(env_fill.get((joint, box), []), count)
        ]
        columns = _slot_columns(self.pm, slot_pairs, pair=True)
        columns.flags.writeable = False
        return layout, self_rows, groups, slot_pairs, env_rows, columns

    def key(self) -> tuple[Any, ...]:
        return ("collision", self.layout, len(self.boxes))

    def fingerprint(self) -> tuple[Any, ...]:
        """The key and the proxy model's joint pairs and limbs, which place each slot's rows
        and clearance parameter."""
        return (*self.key(), self.pm.joint_pairs, self.pm.limb)

    def declare(self, ctx: BuildContext) -> None:
        nlp = ctx.nlp
        margin = nlp.parameter("collision.margin", 1)
        if self.layout.self_slots:
            self._declare_self(ctx)
        if self.layout.env_slots:
            self._declare_env(ctx, margin)

    def _declare_self(self, ctx: BuildContext) -> None:
        """One row per pair of limbs over its joint pairs' slots, in the base frame: self
        distances do not depend on the base, which keeps the base pose and its exponential
        map out of these rows' Hessians."""
        nlp = ctx.nlp
        n = sum(k for *_, k in self.layout.self_slots)
        P = ca.reshape(nlp.parameter("collision.self_slots", 7 * n), 7, n)
        links = self.held_links()
        # per joint pair: how far apart it is held (stance_hold.held_clearance)
        held_p = nlp.parameter("collision.held", len(links))
        held = {k: held_p[m] for m, k in enumerate(links)}
        cap = nlp.parameter("collision.self_cap", len(self._self_rows))
        local = ctx.base_frame_state()
        blocks: list[Block] = []
        s = 0
        for k, (_, slots) in enumerate(self._self_rows):
            for a, b, count in slots:
                clearance = held[self.pm.link_index(a, b)]
                for first in range(s, s + count, SELF_SLOT_BLOCK):
                    blocks.append(Block(k, a, b, P[:, first : first + SELF_SLOT_BLOCK], clearance))
                s += count
        caps = [cap[k] for k in range(len(self._self_rows))]
        value, deriv = self_block_rows(ctx, local, blocks, caps)
        nlp.constrain("collision.self", value, 0.0, np.inf, deriv)

    def _declare_env(self, ctx: BuildContext, margin: Any) -> None:
        """One row per sphere slot and box, saturated: min(d, margin + ENV_SATURATION),
        smoothly (see ENV_SATURATION)."""
        nlp, st = ctx.nlp, ctx.state
        B = ca.reshape(nlp.parameter("collision.boxes", 15 * len(self.boxes)), 15, len(self.boxes))
        n = sum(k for *_, k in self.layout.env_slots)
        Q = ca.reshape(nlp.parameter("collision.env_slots", 4 * n), 4, n)
        points: list[Point] = []
        rows = []
        for joint, box, count in self.layout.env_slots:
            for _ in range(count):
                s = len(points)
                points.append(Point(joint, Q[0:3, s]))
                c = center(st, points[s])
                rows.append(
                    [box_element(c, s, B[:, box], Q[3, s]), Element(margin + ENV_SATURATION)]
                )
        value, deriv = soft_min_rows(ctx, st, points, rows, margin, ctx.base_rotation)
        nlp.constrain("collision.env", value, 0.0, np.inf, deriv)

    def self_groups(self) -> list[tuple[tuple[int, int], list[tuple[int, int]]]]:
        """The self rows, one per pair of limbs (:func:`limbs`), with the sphere pairs held
        in each (none in a row of free slots).

        Rows per pair of limbs rather than per pair of links: fewer rows make IPOPT's linear
        systems smaller (Talos on talos-near-body-collision: 8 instead of 28 rows, the solve
        about 12 % faster in generated C), and the smooth minimum carries a hand sliding from
        one link of a leg to the next; median iterations were 21.5 and 21.0 on two seeds
        (22.5 and 21.0 per pair of links), mean 24.5 and 22.1 (26.1 and 24.1)."""
        return self._groups

    def env_rows(self) -> list[tuple[int, int] | None]:
        """The sphere-box pair of each env row, None for a free slot."""
        return self._env_rows

    def held_links(self) -> list[int]:
        """The joint pairs (indices into ProxyModel.joint_pairs) of the layout, sorted."""
        return sorted({self.pm.link_index(a, b) for a, b, _ in self.layout.self_slots})

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {"collision.margin": np.array([self.margin])}
        if self.layout.self_slots:
            held = held_clearance(problem, self.pm, self.margin)
            out["collision.held"] = held[self.held_links()]
            out["collision.self_slots"] = self._self_parameters()
            groups = self.self_groups()
            out["collision.self_cap"] = np.array([DUMMY_GAP if m else FREE_ROW for _, m in groups])
        if self.layout.env_slots:
            out["collision.boxes"] = np.column_stack(
                [
                    np.concatenate(
                        [b.T_world_box.rotation.ravel(order="F"), b.T_world_box.translation, b.half]
                    )
                    for b in self.boxes
                ]
            )
            out["collision.env_slots"] = self._env_parameters()
        return out

    def bounds(self, problem: Instance) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Rows of free slots only have no lower bound."""
        out = {}
        if self.layout.self_slots:
            lb = np.array([0.0 if members else -np.inf for _, members in self.self_groups()])
            out["collision.self"] = (lb, np.full(lb.shape, np.inf))
        if self.layout.env_slots:
            lb = np.array([-np.inf if pair is None else 0.0 for pair in self.env_rows()])
            out["collision.env"] = (lb, np.full(lb.shape, np.inf))
        return out

    def _self_parameters(self) -> np.ndarray:
        """(7, slots) per slot: sphere a's centre, sphere b's centre (each in its joint's
        frame), r_a + r_b; a free slot: zeros and -DUMMY_GAP."""
        return self._self_columns

    def _env_parameters(self) -> np.ndarray:
        """(4, slots) per slot: the sphere's centre in its joint's frame, its radius (a free
        slot: -DUMMY_GAP, its row saturated, a constant)."""
        return _slot_columns(self.pm, self.env_rows(), pair=False)


def _slot_columns(pm: ProxyModel, slots: list[Any], pair: bool) -> np.ndarray:
    """The slots' sphere parameters, one column each: (7, n) for sphere pairs (i, j) (centres
    of i and j, r_i + r_j) or (4, n) for (sphere, box) slots (centre, radius); a free slot
    (None): zeros and -DUMMY_GAP."""
    rows = 7 if pair else 4
    out = np.zeros((rows, len(slots)))
    out[-1] = -DUMMY_GAP
    live = [k for k, s in enumerate(slots) if s is not None]
    if live:
        idx = np.array([slots[k] for k in live], dtype=int)  # (m, 2)
        centers, radii = pm.centers_local, pm.radii
        out[0:3, live] = centers[idx[:, 0]].T
        if pair:
            out[3:6, live] = centers[idx[:, 1]].T
            out[6, live] = radii[idx[:, 0]] + radii[idx[:, 1]]
        else:
            out[3, live] = radii[idx[:, 0]]
    return out


def _padded(items: list[Any], count: int) -> list[Any]:
    """``items`` and None up to ``count``."""
    return [*items, *([None] * (count - len(items)))]


# a term's filled layout per (proxy model, pairs held, layout given): an active set that
# settled is held again by every call (CollisionTerm._filled)
_FILLS: BoundedCache[tuple[Any, ...]] = BoundedCache("collision fills", 64)
# the rows of a layout per (proxy model, layout); the model is held (Ref)
_ROWS: BoundedCache[list[Any]] = BoundedCache("collision row groups", 64)


def _self_rows(pm: ProxyModel, layout: Layout) -> list[tuple[tuple[int, int], list[Any]]]:
    """The layout's joint pairs grouped by pair of limbs, one row each, sorted."""

    def make() -> list[tuple[tuple[int, int], list[Any]]]:
        limb = pm.limb
        groups: dict[tuple[int, int], list[Any]] = {}
        for a, b, n in layout.self_slots:
            la, lb = (a, b) if limb is None else (int(limb[a]), int(limb[b]))
            groups.setdefault((min(la, lb), max(la, lb)), []).append((a, b, n))
        return sorted(groups.items())

    return _ROWS.get_or_make((Ref(pm), layout), make)


def _self_fill(
    pm: ProxyModel, self_pairs: tuple[tuple[int, int], ...]
) -> dict[tuple[int, int], list[tuple[int, int]]]:
    """The sphere pairs of each joint pair (a, b), sorted, each with its sphere
    on joint a first."""
    joint = pm.joint_ids
    out: dict[tuple[int, int], list[tuple[int, int]]] = {}
    if not self_pairs:
        return out
    ij = np.array(sorted(self_pairs), dtype=int)  # (k, 2)
    a, b = joint[ij[:, 0]], joint[ij[:, 1]]
    swap = ~(a < b)  # the sphere on the smaller joint first
    first = np.where(swap, ij[:, 1], ij[:, 0]).tolist()
    second = np.where(swap, ij[:, 0], ij[:, 1]).tolist()
    lo, hi = np.minimum(a, b).tolist(), np.maximum(a, b).tolist()
    for x, y, i, j in zip(lo, hi, first, second, strict=True):
        out.setdefault((x, y), []).append((i, j))
    return out


def _env_fill(
    pm: ProxyModel, env_pairs: tuple[tuple[int, int], ...]
) -> dict[tuple[int, int], list[tuple[int, int]]]:
    """The sphere-box pairs of each (joint, box), sorted."""
    joint = pm.joint_ids
    out: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for i, k in sorted(env_pairs):
        out.setdefault((int(joint[i]), int(k)), []).append((i, k))
    return out
