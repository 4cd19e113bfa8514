"""The broad phase's records: sphere pairs found close (:class:`Close`), pairs of sphere
groups (:class:`GroupPairs`), the bounding spheres of runs of spheres (:class:`Runs`), and
the selection of each joint pair's closest pairs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# [m] added to a run's bounding radius: its world mean moves with rounding (1e-16 m) that
# the radius, computed once in the joint's frame, does not follow
BOUND_PAD = 1e-9


@dataclass(frozen=True)
class Close:
    """Candidate sphere pairs found close: sphere indices i (of the joint pair's first joint)
    and j, their joint pair (index into ProxyModel.joint_pairs) and distance [m], each (k,)."""

    i: np.ndarray
    j: np.ndarray
    link: np.ndarray
    d: np.ndarray

    def take(self, index: np.ndarray) -> Close:
        """The pairs at ``index`` (a mask or indices)."""
        return Close(self.i[index], self.j[index], self.link[index], self.d[index])

    def fields(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, link, d)."""
        return self.i, self.j, self.link, self.d

    def tuples(self) -> set[tuple[int, int]]:
        """{(min(i, j), max(i, j))}: the pairs as the program holds them."""
        lo, hi = np.minimum(self.i, self.j), np.maximum(self.i, self.j)
        return {(int(a), int(b)) for a, b in zip(lo, hi, strict=True)}


@dataclass(frozen=True)
class GroupPairs:
    """Pairs of sphere groups (ProxyModel's broad phase): their groups ga, gb (n,), joint
    pair (n,), the gap of their bounding spheres (n,) [m], and every group's bounding sphere
    (centres (G, 3), radii (G,))."""

    ga: np.ndarray
    gb: np.ndarray
    link: np.ndarray
    gap: np.ndarray
    gc: np.ndarray
    gr: np.ndarray

    def take(self, index: np.ndarray) -> GroupPairs:
        """The pairs at ``index`` (a mask or indices)."""
        return GroupPairs(
            self.ga[index], self.gb[index], self.link[index], self.gap[index], self.gc, self.gr
        )


def closest(close: Close, per_link: int) -> Close:
    """The ``per_link`` closest pairs of each joint pair among ``close``, sorted by joint
    pair, then distance."""
    order = np.lexsort((close.d, close.link))
    return close.take(order[rank_in_runs(close.link[order]) < per_link])


def rank_in_runs(keys: np.ndarray) -> np.ndarray:
    """(n,) each entry's position in its run of equal ``keys`` (n,), sorted."""
    return np.arange(len(keys)) - np.searchsorted(keys, keys)


@dataclass(frozen=True)
class Runs:
    """Bounding spheres of runs of spheres (a joint's, a group's: each run on one joint).
    A run's radius is that of its local centres, rigid with the joint: the mean of its world
    centres and the same radius (plus BOUND_PAD for rounding) bound it at every posture."""

    starts: np.ndarray  # (m,) first sphere of each non-empty run
    which: np.ndarray  # (m,) its run index
    counts: np.ndarray  # (m,) its number of spheres
    radius: np.ndarray  # (n,) [m] each run's radius (0 for the empty ones)

    @classmethod
    def of(cls, start: np.ndarray, which: np.ndarray, local: np.ndarray, radii: np.ndarray) -> Runs:
        """The runs start[w]:start[w + 1] for w in ``which`` of the local centres (S, 3)."""
        which = np.asarray(which, dtype=int)
        which = which[start[which + 1] > start[which]]
        counts = start[which + 1] - start[which]
        radius = np.zeros(len(start) - 1)
        if len(which):
            mean = np.add.reduceat(local, start[which], axis=0) / counts[:, None]
            rows = np.concatenate([np.arange(start[w], start[w + 1]) for w in which])
            spread = np.linalg.norm(local[rows] - np.repeat(mean, counts, axis=0), axis=1)
            top = np.maximum.reduceat(spread + radii[rows], np.cumsum(counts) - counts)
            radius[which] = top + BOUND_PAD
        return cls(start[which], which, counts, radius)

    def bounds(self, centers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World centres (n, 3) and radii (n,) [m] of the runs for sphere centres (S, 3) in
        world (rows of empty runs unused)."""
        mean = np.zeros((len(self.radius), 3))
        if len(self.which):
            sums = np.add.reduceat(centers, self.starts, axis=0)
            mean[self.which] = sums / self.counts[:, None]
        return mean, self.radius
