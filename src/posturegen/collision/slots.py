"""The collision rows' slots and what fills them: one program per robot and capacity, whatever
pairs an active set holds.

A program's collision rows have a fixed :class:`Capacity`: ``self_blocks`` blocks of
SELF_SLOT_BLOCK sphere-pair slots and ``env_slots`` sphere-box slots. Which two links a block
joins, the spheres of its slots and its joint pair's clearance are *parameters*
(:class:`SelfFill`), as are an env slot's link, sphere and box (:func:`env_parameters`): an
active set that changes never declares, compiles nor loads another
program. The self rows are fixed per robot, one per pair of limbs that has candidate pairs
(:class:`RowTable`), each the smooth minimum of the blocks its parameters give it; the env
rows are one per slot.

A free block or env slot names no link (its link index is -1) and no work is done for it; a
self row that holds no block is the constant FREE_ROW and a free env slot's row the constant
0, both unbounded (a row that varied with q would change the solve even without a bound:
IPOPT writes a row as g(x) - s = 0 with a slack, and its nonlinearity along a step counts as
infeasibility). The capacity grows by doubling when an active set needs more
(:meth:`Capacity.holding`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .._cache import BoundedCache, Ref
from .boxes import EnvBox
from .proxies import ProxyModel

# sphere-pair slots per block: a block joins one pair of links (the active set's
# SELF_PER_LINK closest sphere pairs of a joint pair, then as many violated ones)
SELF_SLOT_BLOCK = 16
# [m] a block's unused slot has the radii sum -DUMMY_GAP (an env slot without a link the
# radius): its distance is about 10 m above the others, its weight in the smooth minimum
# exp(-β·10) = 0 exactly
DUMMY_GAP = 10.0
FREE_ROW = 1.0  # [m] the value of a self row that holds no block
# a column index that lies outside every program's variables: a chain's padding (the indices
# built from it fall outside every target, and a scatter drops what is added there)
PADDING = 10**7
# the capacity a robot's first program of a structure gets. Talos' never-seen reaches
# (`posturegen bench --cold`, 50 problems each): near-body calls hold 27-70 blocks (401 sphere
# pairs at half-sitting, up to 897 after five rounds; one of 50, tightening its margin twice,
# 149), stances 28-80; the box family 16-31 sphere-box pairs. The active set lets go of far
# pairs before it doubles (ActiveSet.term). A free block is not free: a Hessian evaluation
# copies and scatters every block's outputs (Talos: 128 blocks cost 2.5 million instructions
# of a reach's 3.6 million)
FIRST_SELF_BLOCKS = 64
FIRST_ENV_SLOTS = 32


def _doubled(have: int, need: int, first: int) -> int:
    """``have`` (or ``first`` when 0) doubled until it holds ``need`` (0 when none needed
    and none held)."""
    if need <= have:
        return have
    size = have or first
    while size < need:
        size *= 2
    return size


@dataclass(frozen=True)
class Capacity:
    """The slots of a program's collision rows: ``self_blocks`` blocks of SELF_SLOT_BLOCK
    sphere-pair slots, ``env_slots`` sphere-box slots (0: no such rows)."""

    self_blocks: int = 0
    env_slots: int = 0

    def holding(self, self_blocks: int, env_slots: int) -> Capacity:
        """This capacity, each part doubled (from FIRST_SELF_BLOCKS, FIRST_ENV_SLOTS) until it
        holds ``self_blocks`` blocks and ``env_slots`` slots."""
        return Capacity(
            _doubled(self.self_blocks, self_blocks, FIRST_SELF_BLOCKS),
            _doubled(self.env_slots, env_slots, FIRST_ENV_SLOTS),
        )


@dataclass(frozen=True)
class RowTable:
    """A proxy model's links and self rows: ``links`` the joints that carry spheres (a slot's
    link index is a position among them), ``link_of_joint`` the position of each joint (-1:
    none), ``rows`` the pairs of limbs (sorted) of its candidate joint pairs, one self row
    each, and ``row_of_pair`` (P,) the row of each candidate joint pair."""

    links: np.ndarray  # (N,) joint ids
    link_of_joint: np.ndarray  # (njoints,)
    rows: tuple[tuple[int, int], ...]
    row_of_pair: np.ndarray  # (P,)
    # each link's chain: the actuated coordinates (qj) that move it relative to the base,
    # sorted; ``width`` the longest
    chains: tuple[tuple[int, ...], ...] = ()
    width: int = 0
    nz: int = 0  # actuated coordinates (qj)

    @classmethod
    def of(cls, pm: ProxyModel) -> RowTable:
        """The table of ``pm`` (cached per proxy model)."""
        return _TABLES.get_or_make(Ref(pm), lambda: cls._made(pm))

    @classmethod
    def _made(cls, pm: ProxyModel) -> RowTable:
        links = np.unique(pm.joint_ids)
        top = int(max(links.max(initial=0), pm.joint_pairs.max(initial=0))) + 1
        link_of_joint = np.full(top, -1, dtype=int)
        link_of_joint[links] = np.arange(len(links))
        a, b = pm.joint_pairs[:, 0], pm.joint_pairs[:, 1]
        la, lb = (a, b) if pm.limb is None else (pm.limb[a], pm.limb[b])
        key = np.stack([np.minimum(la, lb), np.maximum(la, lb)], axis=1).reshape(-1, 2)
        rows, row_of_pair = np.unique(key, axis=0, return_inverse=True)
        chains = tuple(pm.chains[int(L)] for L in links)
        return cls(
            links,
            link_of_joint,
            tuple((int(x), int(y)) for x, y in rows),
            np.asarray(row_of_pair, dtype=int).ravel(),
            chains,
            max((len(c) for c in chains), default=0),
            1 + max((max(c) for c in pm.chains if c), default=-1),
        )

    def padded_chains(self, base: int = 0) -> np.ndarray:
        """(N, D') each link's chain columns, padded with PADDING; with ``base`` > 0 the
        base's coordinates first (columns 0..base-1) and the chain's shifted by ``base``
        (z = (p_base, w, qj) for base = 6), D' = base + width."""
        out = np.full((len(self.links), base + self.width), PADDING, dtype=np.int64)
        for n, chain in enumerate(self.chains):
            out[n, :base] = np.arange(base)
            out[n, base : base + len(chain)] = np.asarray(chain, dtype=np.int64) + base
        return out


_TABLES: BoundedCache[RowTable] = BoundedCache("collision row tables", 16)


@dataclass(frozen=True)
class SelfFill:
    """The self blocks of a set of held sphere pairs: per block its joint pair (index into
    ProxyModel.joint_pairs) and its sphere pairs (the sphere on the pair's first joint
    first); blocks sorted by joint pair."""

    pairs: tuple[int, ...]  # (blocks,) joint pair of each block
    members: tuple[tuple[tuple[int, int], ...], ...]  # each block's sphere pairs

    @classmethod
    def of(cls, pm: ProxyModel, held: tuple[tuple[int, int], ...]) -> SelfFill:
        """The blocks of the held sphere pairs (i, j) (cached per model and pairs)."""
        return _FILLS.get_or_make((Ref(pm), held), lambda: cls._made(pm, held))

    @classmethod
    def _made(cls, pm: ProxyModel, held: tuple[tuple[int, int], ...]) -> SelfFill:
        if not held:
            return cls((), ())
        joint = pm.joint_ids
        ij = np.array(sorted(held), dtype=int)  # (k, 2)
        a, b = joint[ij[:, 0]], joint[ij[:, 1]]
        swap = a > b  # the sphere on the smaller joint first
        first = np.where(swap, ij[:, 1], ij[:, 0])
        second = np.where(swap, ij[:, 0], ij[:, 1])
        link = pm.link_indices(a, b)  # (k,)
        order = np.lexsort((second, first, link))
        link, first, second = link[order], first[order].tolist(), second[order].tolist()
        starts = np.flatnonzero(np.r_[True, link[1:] != link[:-1]]).tolist() + [len(link)]
        pairs: list[int] = []
        members: list[tuple[tuple[int, int], ...]] = []
        for lo, hi in zip(starts[:-1], starts[1:], strict=True):  # each joint pair's run
            for s in range(lo, hi, SELF_SLOT_BLOCK):
                e = min(s + SELF_SLOT_BLOCK, hi)
                pairs.append(int(link[lo]))
                members.append(tuple(zip(first[s:e], second[s:e], strict=True)))
        return cls(tuple(pairs), tuple(members))

    @property
    def blocks(self) -> int:
        """Blocks needed."""
        return len(self.pairs)

    @functools.cached_property
    def _slot_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(m,) each held sphere pair's slot (its block's first slot + its place in it) and
        (m, 2) its spheres, block after block (made once per fill: a fill is shared)."""
        col = np.concatenate(
            [b * SELF_SLOT_BLOCK + np.arange(len(m)) for b, m in enumerate(self.members)]
        )
        ij = np.array([p for m in self.members for p in m], dtype=int)  # (m, 2)
        col.flags.writeable = ij.flags.writeable = False
        return col, ij

    def parameters(
        self, pm: ProxyModel, table: RowTable, capacity: int, held: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The self blocks' parameters in ``capacity`` blocks, with each joint pair held
        ``held`` (P,) [m] apart: ``links`` (2, B) link indices (-1: free), ``rows`` (B,) each
        block's row (-1: free), ``slots`` (7, 16·B) sphere centres in their joints' frames and
        radii sums (free: zeros and -DUMMY_GAP), ``clear`` (B,) [m], ``free`` (R,) 1 for a row
        that holds no block, ``index`` (:func:`block_indices`)."""
        B, n = capacity, self.blocks
        links = np.full((2, B), -1.0)
        rows = np.full(B, -1.0)
        clear = np.zeros(B)
        slots = np.zeros((7, SELF_SLOT_BLOCK * B))
        slots[6] = -DUMMY_GAP
        free = np.ones(len(table.rows))
        if n:
            k = np.array(self.pairs, dtype=int)
            links[:, :n] = table.link_of_joint[pm.joint_pairs[k]].T
            rows[:n] = table.row_of_pair[k]
            free[table.row_of_pair[k]] = 0.0
            clear[:n] = held[k]
            col, ij = self._slot_pairs
            centers, radii = pm.centers_local, pm.radii
            slots[0:3, col] = centers[ij[:, 0]].T
            slots[3:6, col] = centers[ij[:, 1]].T
            slots[6, col] = radii[ij[:, 0]] + radii[ij[:, 1]]
        index = _INDICES.get_or_make(
            (Ref(self), Ref(table), B), lambda: block_indices(table, links)
        )
        return {
            "links": links,
            "rows": rows,
            "slots": slots,
            "clear": clear,
            "free": free,
            "index": index,
        }

    def row_members(self, table: RowTable) -> list[list[tuple[int, int]]]:
        """The sphere pairs held in each self row (empty: a free row)."""
        out: list[list[tuple[int, int]]] = [[] for _ in table.rows]
        for k, members in zip(self.pairs, self.members, strict=True):
            out[int(table.row_of_pair[k])].extend(members)
        return out


_FILLS: BoundedCache[SelfFill] = BoundedCache("collision self fills", 64)
# the index parameters of each fill's blocks per capacity (read-only)
_INDICES: BoundedCache[np.ndarray] = BoundedCache("collision block indices", 64)


def _consecutive(sizes: dict[str, int]) -> dict[str, slice]:
    """Slices of the given sizes, one after the other, by name."""
    out, k = {}, 0
    for name, size in sizes.items():
        out[name] = slice(k, k + size)
        k += size
    return out


def index_rows(width: int) -> dict[str, slice]:
    """Where each index set of a block stands in :func:`block_indices`' rows."""
    return _consecutive({"pose": 24, "jacobian": 12 * width, "chain": 2 * width})


def block_indices(table: RowTable, links: np.ndarray) -> np.ndarray:
    """(K, B) each block's indices (:func:`index_rows`): where its links' poses are in the
    pose table (12 per link: position, rotation column-major), where their compressed twist
    Jacobians are (6·D per link), and its links' chains (D each, padded with PADDING: where
    its results go). A free block reads entry 0 and has an empty chain."""
    D = table.width
    at = index_rows(D)
    B = links.shape[1]
    out = np.zeros((at["chain"].stop, B))
    out[at["chain"]] = PADDING
    held = np.flatnonzero(links[0] >= 0)
    if not len(held):
        return out
    ia, ib = links[0, held].astype(np.int64), links[1, held].astype(np.int64)
    chains = table.padded_chains()  # (N, D)
    twelve, six_d = np.arange(12)[:, None], np.arange(6 * D)[:, None]
    out[at["pose"], :][:, held] = np.vstack([12 * ia + twelve, 12 * ib + twelve])
    out[at["jacobian"], :][:, held] = np.vstack([6 * D * ia + six_d, 6 * D * ib + six_d])
    out[at["chain"], :][:, held] = np.vstack([chains[ia].T, chains[ib].T])
    out.flags.writeable = False
    return out


def env_parameters(
    pm: ProxyModel,
    table: RowTable,
    pairs: tuple[tuple[int, int], ...],
    boxes: list[EnvBox],
    capacity: int,
) -> np.ndarray:
    """(20, E) per env slot: its link index (-1: free), the sphere's centre in its joint's
    frame, its radius (free: -DUMMY_GAP), the box's rotation (column-major), centre and half
    sizes (free: the unit box at the origin)."""
    out = np.zeros((20, capacity))
    out[0] = -1.0
    out[4] = -DUMMY_GAP
    out[5:14] = np.eye(3).ravel(order="F")[:, None]
    out[17:20] = 1.0
    if pairs:
        ik = np.array(pairs, dtype=int)  # (m, 2) sphere, box
        m = len(ik)
        out[0, :m] = table.link_of_joint[pm.joint_ids[ik[:, 0]]]
        out[1:4, :m] = pm.centers_local[ik[:, 0]].T
        out[4, :m] = pm.radii[ik[:, 0]]
        box = np.array(
            [
                np.concatenate(
                    [b.T_world_box.rotation.ravel(order="F"), b.T_world_box.translation, b.half]
                )
                for b in boxes
            ]
        ).reshape(-1, 15)
        out[5:20, :m] = box[ik[:, 1]].T
    return out


# z = (p_base (3,), w (3,), qj): the env rows' variables, the base's columns before the joints'
BASE_COLUMNS = 6


def env_index_rows(width: int) -> dict[str, slice]:
    """Where each index set of an env slot stands in :func:`env_indices`' rows (``width``
    its link's columns in z = (p_base, w, qj): the base's six and the chain's)."""
    return _consecutive({"pose": 12, "jacobian": 6 * width, "chain": width})


def env_indices(table: RowTable, links: np.ndarray) -> np.ndarray:
    """(K, E) each env slot's indices (:func:`env_index_rows`): where its link's pose and
    compressed twist Jacobian (on z = (p_base, w, qj)) are, and its link's columns in z
    (padded with PADDING). A free slot reads entry 0 and has no columns."""
    chains = table.padded_chains(BASE_COLUMNS)  # (N, D)
    D = chains.shape[1]
    at = env_index_rows(D)
    out = np.zeros((at["chain"].stop, len(links)))
    out[at["chain"]] = PADDING
    live = np.flatnonzero(links >= 0)
    if not len(live):
        return out
    link = links[live].astype(np.int64)
    out[at["pose"], :][:, live] = 12 * link + np.arange(12)[:, None]
    out[at["jacobian"], :][:, live] = 6 * D * link + np.arange(6 * D)[:, None]
    out[at["chain"], :][:, live] = chains[link].T
    out.flags.writeable = False
    return out
