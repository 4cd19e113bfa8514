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

Self rows are one per pair of limbs (the kinematic chains between branchings, fixed per
robot): a smooth minimum (-LSE, SOFT_MIN_BETA) of its sphere pairs' distances minus each
pair's clearance, computed in the base frame, over blocks of 16 slots
(:mod:`posturegen.collision.self_blocks`); env rows are one per sphere-box slot
(:mod:`posturegen.collision.env_slots`). Both bring their own exact Jacobian and Hessian
(through the links' twist Jacobians; tested equal to CasADi's).

Rows are kept few by an active set: of the pairs closer than ``activation`` beyond their
clearance (self pairs; ``environment_activation`` beyond the margin for sphere-box pairs) at
the current posture, the closest few of each pair of links enter the program
(:mod:`posturegen.collision.active_set`); after a solve every candidate pair is checked and
the violated ones are added before solving again (:func:`posturegen.solver.solve.solve`).

The pairs held are *parameters* of slots (:mod:`posturegen.collision.slots`): which links a
block joins, its spheres, its clearance and its row. The program's structure is only its
:class:`~posturegen.collision.slots.Capacity`, so a robot's program of a contact structure
is built once and serves every active set that fits it (the capacity doubles when one does
not).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ..terms.nlp import BuildContext, Instance, Term
from .boxes import EnvBox
from .env_slots import env_rows
from .env_slots import kernels as env_kernels
from .joint_maps import JointMap
from .native import have, ready
from .proxies import ProxyModel
from .self_blocks import INDEX_NAMES, self_rows
from .self_blocks import kernels as self_kernels
from .slots import (
    BASE_COLUMNS,
    SELF_SLOT_BLOCK,
    Capacity,
    RowTable,
    SelfFill,
    env_index_rows,
    env_indices,
    env_parameters,
    index_rows,
)
from .stance_hold import held_clearance


@dataclass
class CollisionTerm(Term):
    """Rows d >= margin for the held sphere pairs and sphere-box pairs (see module doc), in
    the slots of ``capacity`` (grown to hold them)."""

    pm: ProxyModel
    self_pairs: tuple[tuple[int, int], ...]
    env_pairs: tuple[tuple[int, int], ...]  # (sphere, box index)
    boxes: list[EnvBox]
    margin: float
    capacity: Capacity = field(default_factory=Capacity)
    self_collision: bool = True  # whether the program has self rows
    # the robot's joint maps (posturegen.collision.joint_maps), and whether each one's rows
    # hold (its pair checked and its joints near a disc: ActiveSet.maps_on; else unbounded)
    maps: tuple[JointMap, ...] = ()
    mapped: tuple[bool, ...] = ()
    name: str = "collision"
    late: ClassVar[bool] = True  # declared on the program of the others (their cache shared)

    def __post_init__(self) -> None:
        self.table = RowTable.of(self.pm)
        self.fill = SelfFill.of(self.pm, self.self_pairs)
        # a program with self rows (env rows) has blocks (slots) even before it holds pairs
        self.capacity = self.capacity.holding(
            max(self.fill.blocks, 1) if self.self_collision else 0,
            max(len(self.env_pairs), 1) if self.boxes else 0,
        )

    def key(self) -> tuple[Any, ...]:
        maps = tuple((m.joints, m.digest) for m in self._maps())
        return ("collision", self.capacity.self_blocks, self.capacity.env_slots, maps)

    def _maps(self) -> tuple[JointMap, ...]:
        """The joint maps whose rows the program has (with its self rows)."""
        return self.maps if self.capacity.self_blocks else ()

    def fingerprint(self) -> tuple[Any, ...]:
        """The key and what the declaration reads of the proxy model: the joints that carry
        spheres (a slot's link index is a position among them), the rows' pairs of limbs, the
        links' chains."""
        t = self.table
        return (*self.key(), t.links, t.rows, t.chains)

    def declare(self, ctx: BuildContext) -> None:
        nlp = ctx.nlp
        margin = nlp.parameter("collision.margin", 1)
        B, E, D = self.capacity.self_blocks, self.capacity.env_slots, self.table.width
        native_self, native_env = self._native(ctx)
        if B:
            params = [
                ca.reshape(nlp.parameter("collision.self_links", 2 * B), 2, B),
                nlp.parameter("collision.self_rows", B),
                ca.reshape(
                    nlp.parameter("collision.self_slots", 7 * SELF_SLOT_BLOCK * B),
                    7,
                    SELF_SLOT_BLOCK * B,
                ),
                nlp.parameter("collision.self_clear", B),
                nlp.parameter("collision.self_free", len(self.table.rows)),
            ]
            at = index_rows(D)
            for name in INDEX_NAMES:
                size = at[name].stop - at[name].start
                params.append(
                    ca.reshape(nlp.parameter(f"collision.self_at_{name}", size * B), size, B)
                )
            # self distances do not depend on the base: computed in its frame, which keeps the
            # base pose and its exponential map out of these rows' Hessians
            value, deriv = self_rows(ctx, ctx.base_frame_state(), self.table, params, native_self)
            nlp.constrain("collision.self", value, 0.0, np.inf, deriv)
        if self._maps():
            rows = ca.vertcat(*[m.rows(ctx.joints) for m in self._maps()])
            nlp.constrain("collision.joint_maps", rows, 0.0, np.inf)
        if E:
            slots = ca.reshape(nlp.parameter("collision.env_slots", 20 * E), 20, E)
            rows = env_index_rows(BASE_COLUMNS + D)["chain"].stop
            index = ca.reshape(nlp.parameter("collision.env_index", rows * E), rows, E)
            value, deriv = env_rows(ctx, ctx.state, self.table, slots, index, margin, native_env)
            nlp.constrain("collision.env", value, 0.0, np.inf, deriv)

    def _native(self, ctx: BuildContext) -> tuple[bool, bool]:
        """Whether the self rows and the env rows run their kernels in machine code: in a
        program for the virtual machine (BuildContext.native_kernels), once they are compiled
        (posturegen.collision.native: those missing are sent to a builder process, and the
        virtual machine runs them until then)."""
        if not ctx.native_kernels:
            return False, False
        n_links, nz, D = len(self.table.links), ctx.joints.shape[0], self.table.width
        own = (
            self_kernels(n_links, nz, len(self.table.rows), D) if self.capacity.self_blocks else []
        )
        env = env_kernels(n_links, nz, D) if self.capacity.env_slots else []
        ready(own + env)
        out = have(own), have(env)
        ctx.kernels_pending = ctx.kernels_pending or not all(out)
        return out

    def self_groups(self) -> list[tuple[tuple[int, int], list[tuple[int, int]]]]:
        """The self rows, one per pair of limbs, with the sphere pairs held in each (none in
        a free row).

        Rows per pair of limbs rather than per pair of links: fewer rows make IPOPT's linear
        systems smaller (Talos on talos-near-body-collision: 8 instead of 28 rows, the solve
        about 12 % faster in generated C), and the smooth minimum carries a hand sliding from
        one link of a leg to the next; median iterations were 21.5 and 21.0 on two seeds
        (22.5 and 21.0 per pair of links), mean 24.5 and 22.1 (26.1 and 24.1)."""
        if not self.capacity.self_blocks:
            return []
        return list(zip(self.table.rows, self.fill.row_members(self.table), strict=True))

    def map_rows(self) -> list[tuple[JointMap, bool]]:
        """Each joint map of the program's rows (in order) with whether its rows hold (its pair
        checked in this problem)."""
        return list(zip(self._maps(), self.mapped or (True,) * len(self.maps), strict=True))

    def env_rows(self) -> list[tuple[int, int] | None]:
        """The sphere-box pair of each env row, None for a free slot."""
        pairs: list[tuple[int, int] | None] = list(self.env_pairs)
        return pairs + [None] * (self.capacity.env_slots - len(pairs))

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {"collision.margin": np.array([self.margin])}
        if self.capacity.self_blocks:
            held = held_clearance(problem, self.pm, self.margin)
            fill = self.fill.parameters(self.pm, self.table, self.capacity.self_blocks, held)
            for name in ("links", "rows", "slots", "clear", "free"):
                out[f"collision.self_{name}"] = fill[name]
            at = index_rows(self.table.width)
            for name in INDEX_NAMES:
                out[f"collision.self_at_{name}"] = fill["index"][at[name]]
        if self.capacity.env_slots:
            slots = env_parameters(
                self.pm, self.table, self.env_pairs, self.boxes, self.capacity.env_slots
            )
            out["collision.env_slots"] = slots
            out["collision.env_index"] = env_indices(self.table, slots[0])
        return out

    def bounds(self, problem: Instance) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Free rows have no lower bound."""
        out = {}
        if self.capacity.self_blocks:
            lb = np.array([0.0 if members else -np.inf for _, members in self.self_groups()])
            out["collision.self"] = (lb, np.full(lb.shape, np.inf))
        if self._maps():
            lb = np.concatenate(
                [np.full(len(m.discs), 0.0 if on else -np.inf) for m, on in self.map_rows()]
            )
            out["collision.joint_maps"] = (lb, np.full(lb.shape, np.inf))
        if self.capacity.env_slots:
            lb = np.array([-np.inf if pair is None else 0.0 for pair in self.env_rows()])
            out["collision.env"] = (lb, np.full(lb.shape, np.inf))
        return out
