"""A robot's sphere proxies (:mod:`posturegen.collision.proxy_fit`), cached, and its candidate
self-collision pairs: every pair of spheres of two joints that the pair rule
(:mod:`posturegen.collision.pairs`) leaves checked.

Each pair of joints has a *clearance* [m]: how far apart its proxies are at the reference
posture. A pair whose proxies are closer there than the collision margin is held at least
that far apart instead of the margin (the reference itself stays feasible); one whose
proxies overlap there (their meshes do not: else they would be unchecked) is held no deeper
than there minus SLIDE, and the mesh check decides.
"""

from __future__ import annotations

import hashlib
import importlib.resources
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..model.robot import Robot
from . import pairs, proxy_fit, sphere_kernel, surface
from .broad_phase import Close, GroupPairs, Runs, closest, rank_in_runs
from .pairs import PairRule, pair_rule
from .proxy_fit import PROXY_VERSION, Sphere, fit_robot


def cache_dir() -> Path:
    """Where fitted proxies are cached: $POSTUREGEN_CACHE, else ~/.cache/posturegen."""
    root = os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen"
    return Path(root) / "proxies"


# [m] how much deeper than at the reference posture a pair whose proxies overlap there (its
# meshes do not) may go: turning the joint between them slides the spheres of one face along
# those of the other, whose bulges come and go by up to the excess; held at the reference
# itself, HRP-2's hips (meshes 1.3 mm apart, proxies -15.6 mm) kept its stand-reach from
# bending (IPOPT infeasible at every margin; verified with 1 or 2 cm)
SLIDE = 0.01
GROUP = 16  # spheres per group of the broad phase (a joint's spheres split by their extent)
# group pairs of each joint pair measured first by ProxyModel.closest_pairs (the nearest by
# their bounding spheres): their pairs bound the distance of the ones kept
FIRST_GROUPS = 3


@dataclass
class ProxyModel:
    """Sphere proxies of a robot (sorted by joint, then by group of the broad phase) and its
    candidate self-collision pairs: every pair of spheres of the candidate joint pairs, never
    listed (Talos: 3 million), found by a broad phase on joints, then groups of GROUP spheres."""

    spheres: list[Sphere]
    joint_pairs: np.ndarray  # (P, 2) candidate joint pairs (sorted ids)
    clearance: np.ndarray  # (P,) [m] their proxies' distance at the reference posture
    rule: PairRule
    # (njoints,) limb of each joint (see limbs()); None: every joint its own limb
    limb: np.ndarray | None = None
    report: dict[str, Any] = field(default_factory=dict)  # the fit's refinement report
    # each joint's chain: the actuated coordinates (indices into qj) of the joints between it
    # and the base, sorted (see chains())
    chains: tuple[tuple[int, ...], ...] = ()
    key: str = ""  # the fit's digest (_cache_key): what the robot's proxies were fitted from

    def __post_init__(self) -> None:
        groups = _grouped(self.spheres)  # spheres reordered: joints and groups contiguous
        self.spheres = [self.spheres[k] for g in groups for k in g]
        self._joint = np.array([s.joint_id for s in self.spheres], dtype=int)  # (S,)
        self._local = np.array([s.center for s in self.spheres]).reshape(-1, 3)  # (S, 3)
        self._radii = np.array([s.radius for s in self.spheres])  # (S,)
        self._joints = np.unique(self._joint)  # the joints that carry spheres
        self._joint_list = [int(j) for j in self._joints]
        self._joint_start = np.searchsorted(self._joint, np.arange(self._joint.max(initial=0) + 2))
        sizes = np.array([len(g) for g in groups], dtype=int)
        self._group_start = np.concatenate([[0], np.cumsum(sizes)])  # (G + 1,)
        self._group_joint = self._joint[self._group_start[:-1]]  # (G,)
        self._members = np.full((len(groups), GROUP), -1, dtype=int)  # (G, GROUP)
        for g, (start, size) in enumerate(zip(self._group_start[:-1], sizes, strict=True)):
            self._members[g, :size] = np.arange(start, start + size)
        # each joint pair's group pairs, contiguous: (ga, gb) for ga of a, gb of b
        ga, gb, link = [], [], []
        for k, (a, b) in enumerate(self.joint_pairs):
            A, B = np.flatnonzero(self._group_joint == a), np.flatnonzero(self._group_joint == b)
            ga.append(np.repeat(A, len(B)))
            gb.append(np.tile(B, len(A)))
            link.append(np.full(len(A) * len(B), k))
        self._ga = np.concatenate(ga) if ga else np.zeros(0, dtype=int)
        self._gb = np.concatenate(gb) if gb else np.zeros(0, dtype=int)
        self._gp_link = np.concatenate(link) if link else np.zeros(0, dtype=int)
        self._gp_start = np.searchsorted(self._gp_link, np.arange(len(self.joint_pairs) + 1))
        top = int(self.joint_pairs.max(initial=self._joint.max(initial=0))) + 1
        self._pair_table = np.full((top, top), -1, dtype=int)  # (lo, hi) -> joint pair index
        if len(self.joint_pairs):
            self._pair_table[self.joint_pairs[:, 0], self.joint_pairs[:, 1]] = np.arange(
                len(self.joint_pairs)
            )
        self._joint_runs = Runs.of(self._joint_start, self._joints, self._local, self._radii)
        self._group_runs = Runs.of(
            self._group_start, np.arange(len(sizes)), self._local, self._radii
        )
        self._compiled: sphere_kernel.SphereSearch | None = None

    def pair_clearance(self, margin: float) -> np.ndarray:
        """(P,) [m] how far apart each candidate joint pair is held: min(margin, clearance),
        or, for a pair whose proxies overlap at the reference, clearance - SLIDE."""
        return np.where(
            self.clearance < 0, self.clearance - SLIDE, np.minimum(margin, self.clearance)
        )

    def link_index(self, a: int, b: int) -> int:
        """The index of joint pair (a, b) (either order) in ``joint_pairs``."""
        return int(self.link_indices(np.array([a]), np.array([b]))[0])

    def link_indices(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(k,) the indices of joint pairs (a, b) (each (k,), either order) in
        ``joint_pairs``; a KeyError for a pair that is not a candidate."""
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        k = self._pair_table[lo, hi]
        if np.any(k < 0):
            bad = int(np.flatnonzero(k < 0)[0])
            raise KeyError((int(lo[bad]), int(hi[bad])))
        return k

    def centers_world(self, model: pin.Model, data: pin.Data) -> np.ndarray:
        """(S, 3) sphere centres in world for the placements already in ``data.oMi``:
        c_world = R_j·c + p_j of each sphere's joint j."""
        T = np.zeros((model.njoints, 4, 4))
        oMi = data.oMi
        T[self._joints] = [oMi[j].homogeneous for j in self._joint_list]
        T = T[self._joint]  # (S, 4, 4)
        return np.einsum("sij,sj->si", T[:, :3, :3], self._local) + T[:, :3, 3]

    def close_pairs(
        self, centers: np.ndarray, slack: np.ndarray, links: np.ndarray | None = None
    ) -> Close:
        """The candidate sphere pairs closer than their joint pair's ``slack`` (P,) [m],
        among the joint pairs ``links`` (indices, default all), for sphere centres (S, 3) in
        world. Joint pairs, then pairs of groups, whose bounding spheres are farther apart
        than the slack (a lower bound of every distance between their spheres) are skipped."""
        if (search := self._search()) is not None:
            found = search.close(centers, *self._bounds(centers), slack, self._links(links))
            return self._measured(centers, *found)
        groups = self._group_pairs(centers, slack, links)
        return self._sphere_pairs(centers, groups, slack[groups.link])

    def closest_pairs(
        self,
        centers: np.ndarray,
        slack: np.ndarray,
        per_link: int,
        links: np.ndarray | None = None,
    ) -> Close:
        """``closest(close_pairs(centers, slack, links), per_link)``, without measuring every
        pair within the slack (Talos' hand at its thigh: 29,000 sphere pairs measured for the
        400 kept). First the pairs of each joint pair's FIRST_GROUPS nearest group pairs
        give T, its per_link-th smallest distance so far (the slack while fewer): an upper
        bound of the per_link-th smallest of all; then only the pairs that their bounding
        spheres leave below T are measured."""
        if (search := self._search()) is not None:
            ordered = np.sort(self._links(links))  # the pairs sorted by joint pair
            found = search.close(centers, *self._bounds(centers), slack, ordered, per_link)
            return self._measured(centers, *found)
        groups = self._group_pairs(centers, slack, links)
        order = np.lexsort((groups.gap, groups.link))
        first = np.zeros(len(order), dtype=bool)
        first[order[rank_in_runs(groups.link[order]) < FIRST_GROUPS]] = True
        found = self._sphere_pairs(centers, groups.take(first), slack[groups.link[first]])
        bound = np.array(slack, dtype=float)  # (P,) [m] T of each joint pair
        near = closest(found, per_link)  # sorted by joint pair, then distance
        kth = rank_in_runs(near.link) == per_link - 1
        bound[near.link[kth]] = np.minimum(bound[near.link[kth]], near.d[kth])
        rest = groups.take(~first & (groups.gap <= bound[groups.link]))
        more = self._sphere_pairs(centers, rest, bound[rest.link])
        pairs = zip(found.fields(), more.fields(), strict=True)
        both = Close(*(np.concatenate([a, b]) for a, b in pairs))
        return closest(both, per_link)

    def _search(self) -> sphere_kernel.SphereSearch | None:
        """The compiled search of these proxies (made at first use), or None without it."""
        if not sphere_kernel.available():
            return None
        if self._compiled is None:
            self._compiled = sphere_kernel.SphereSearch(
                self._radii,
                self.joint_pairs,
                self._gp_start,
                self._ga,
                self._gb,
                self._group_start,
            )
        return self._compiled

    def _measured(
        self, centers: np.ndarray, i: np.ndarray, j: np.ndarray, link: np.ndarray
    ) -> Close:
        """The pairs (i, j) of joint pairs ``link`` found by the compiled search, their
        distances measured here as the numpy search measures them (bit for bit: the C sums
        differ in the last bit, and a pair's distance sets its hold in the program, where
        IPOPT's path follows it: HRP-2's vertical ladder failed a stage on such bits)."""
        return Close(i, j, link, self.distances(centers, i, j))

    def _bounds(
        self, centers: np.ndarray
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The groups' and the joints' bounding spheres (centres, radii) for centres (S, 3)."""
        return self._group_runs.bounds(centers), self._joint_runs.bounds(centers)

    def _links(self, links: np.ndarray | None) -> np.ndarray:
        """The joint pair indices ``links`` (default all)."""
        return np.arange(len(self.joint_pairs)) if links is None else np.asarray(links, dtype=int)

    def _group_pairs(
        self, centers: np.ndarray, slack: np.ndarray, links: np.ndarray | None
    ) -> GroupPairs:
        """The pairs of groups of the joint pairs ``links`` (default all) whose bounding
        spheres are closer than their joint pair's ``slack`` (P,) [m] (joint pairs first)."""
        k = self._links(links)
        jc, jr = self._joint_runs.bounds(centers)
        a, b = self.joint_pairs[k, 0], self.joint_pairs[k, 1]
        gap = np.linalg.norm(jc[a] - jc[b], axis=1) - jr[a] - jr[b]
        k = k[gap < slack[k]]  # the joint pairs that pass
        first, count = self._gp_start[k], self._gp_start[k + 1] - self._gp_start[k]
        gp = np.arange(count.sum()) + np.repeat(first - (np.cumsum(count) - count), count)
        gc, gr = self._group_runs.bounds(centers)
        ga, gb, link = self._ga[gp], self._gb[gp], self._gp_link[gp]
        gap = np.linalg.norm(gc[ga] - gc[gb], axis=1) - gr[ga] - gr[gb]
        ok = gap < slack[link]  # the group pairs that pass
        return GroupPairs(ga[ok], gb[ok], link[ok], gap[ok], gc, gr)

    def _sphere_pairs(self, centers: np.ndarray, groups: GroupPairs, bound: np.ndarray) -> Close:
        """The sphere pairs of the group pairs ``groups`` closer than their ``bound`` (n,) [m]:
        each sphere against the other group's bounding sphere, then the pairs of survivors."""
        ga, gb, link, gc, gr = groups.ga, groups.gb, groups.link, groups.gc, groups.gr
        ma, mb = self._members[ga], self._members[gb]  # (n, GROUP), -1: no sphere
        near_a = self._near_bound(centers, ma, gc[gb], gr[gb], bound)
        near_b = self._near_bound(centers, mb, gc[ga], gr[ga], bound)
        row, s, t = np.nonzero(near_a[:, :, None] & near_b[:, None, :])
        i, j, link = ma[row, s], mb[row, t], link[row]
        d = self.distances(centers, i, j)
        keep = d < bound[row]
        return Close(i[keep], j[keep], link[keep], d[keep])

    def _near_bound(
        self,
        centers: np.ndarray,
        members: np.ndarray,
        bound_c: np.ndarray,
        bound_r: np.ndarray,
        slack: np.ndarray,
    ) -> np.ndarray:
        """(n, GROUP) which spheres of each row's group ``members`` (n, GROUP) are closer than
        ``slack`` (n,) [m] to the row's other group's bounding sphere (centre (n, 3), radius
        (n,)): a lower bound of their distance to each sphere of that group."""
        valid = members >= 0
        u = centers[members] - bound_c[:, None, :]  # (n, GROUP, 3)
        gap = np.sqrt(np.einsum("nkj,nkj->nk", u, u)) - self._radii[members] - bound_r[:, None]
        return valid & (gap < slack[:, None])

    def distances(self, centers: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Distances |c_i - c_j| - r_i - r_j [m] of sphere pairs (indices i, j)."""
        u = centers[i] - centers[j]
        return np.sqrt(np.einsum("ij,ij->i", u, u)) - self._radii[i] - self._radii[j]

    def links_of(self, excluded: set[tuple[int, int]] | frozenset[tuple[int, int]]) -> np.ndarray:
        """Indices of the candidate joint pairs that are not ``excluded`` (sorted ids)."""
        if not excluded:
            return np.arange(len(self.joint_pairs))
        gone = np.array(sorted(excluded), dtype=int).reshape(-1, 2)
        kept = ~_rows_in(self.joint_pairs, gone)
        return np.flatnonzero(kept)

    @property
    def centers_local(self) -> np.ndarray:
        """(S, 3) sphere centres [m], each in its joint's frame."""
        return self._local

    @property
    def radii(self) -> np.ndarray:
        """(S,) radii [m]."""
        return self._radii

    @property
    def joint_ids(self) -> np.ndarray:
        """(S,) each sphere's joint."""
        return self._joint


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(n,) whether each row (a, b) of ``rows`` (n, 2) of ints is a row of ``table`` (m, 2)."""
    width = int(max(rows.max(initial=0), table.max(initial=0))) + 1
    return np.isin(rows[:, 0] * width + rows[:, 1], table[:, 0] * width + table[:, 1])


def _grouped(spheres: list[Sphere]) -> list[list[int]]:
    """Groups of at most GROUP sphere indices, each of one joint, by joint: a joint's
    spheres split at the median of their centres along their widest extent until small."""
    out: list[list[int]] = []
    by_joint: dict[int, list[int]] = {}
    for k, s in enumerate(spheres):
        by_joint.setdefault(s.joint_id, []).append(k)
    for j in sorted(by_joint):
        todo = [np.array(by_joint[j])]
        while todo:
            idx = todo.pop()
            if len(idx) <= GROUP:
                out.append([int(k) for k in idx])
                continue
            c = np.array([spheres[k].center for k in idx])
            axis = int(np.argmax(np.ptp(c, axis=0)))
            order = idx[np.argsort(c[:, axis], kind="stable")]
            todo += [order[len(order) // 2 :], order[: len(order) // 2]]
    return out


def _cache_key(robot: Robot) -> str:
    """A digest of what the fit depends on: the fitting code itself (its modules' sources:
    any change of a constant or a step fits anew), the URDF, the SRDF and the collision
    meshes' files (the proxies cover their surfaces: an edited mesh is fitted anew)."""
    h = hashlib.sha1(f"v{PROXY_VERSION}".encode())
    for module in (proxy_fit, surface, pairs):
        h.update(Path(str(module.__file__)).read_bytes())
    for path in (robot.urdf, robot.srdf):
        if path is not None:
            h.update(Path(path).read_bytes())
    for mesh in mesh_files(robot.collision_model()):
        h.update(mesh.name.encode() + b"\0")  # not the folder: a moved install keeps them
        h.update(mesh.read_bytes())
    return h.hexdigest()[:16]


def mesh_files(geometry: pin.GeometryModel) -> list[Path]:
    """The mesh files of a geometry model, sorted (its primitive shapes have none: their
    sizes are in the URDF). Talos' 24 files, 0.8 MB, hash in 1.6 ms; G1's 18 MB in 15 ms,
    against 1.4 s to load them."""
    paths = {Path(g.meshPath) for g in geometry.geometryObjects if g.meshPath}
    return sorted(p for p in paths if p.is_absolute() and p.is_file())


def robot_spheres(
    robot: Robot, rule: PairRule, key: str | None = None
) -> tuple[list[Sphere], dict[str, Any]]:
    """The robot's proxies (:func:`posturegen.collision.proxy_fit.fit_robot`), fitted once and
    cached on disk (:func:`cache_dir`) under ``key`` (default: :func:`_cache_key`); and the
    fit's report."""
    key = key or _cache_key(robot)
    path = cache_dir() / f"{key}.json"
    if path.is_file():
        try:
            raw = json.loads(path.read_text())
            spheres = [
                Sphere(
                    int(s["joint"]), np.array(s["center"]), float(s["radius"]), float(s["excess"])
                )
                for s in raw["spheres"]
            ]
            return spheres, dict(raw.get("report", {}))
        except (OSError, ValueError, KeyError, TypeError):
            pass  # a broken cache file: fit again
    shipped = read_shipped(key)
    if shipped is not None:
        return shipped
    spheres, report = fit_robot(robot.model, robot.collision_model(), rule)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(
            json.dumps(
                {
                    "version": PROXY_VERSION,
                    "spheres": [
                        {
                            "joint": s.joint_id,
                            "center": s.center.tolist(),
                            "radius": s.radius,
                            "excess": s.excess,
                        }
                        for s in spheres
                    ],
                    "report": report,
                }
            )
        )
    except OSError:
        pass  # a read-only home: fit again next time
    return spheres, report


def shipped_dir() -> Path:
    """Folder ``data/proxies`` of posturegen: the bundled robots' proxies, fitted before
    release (``tools/ship_proxies.py``), one ``<key>.npz`` per robot (:func:`_cache_key`: a
    robot whose meshes, URDF or fitting code differ finds none and is fitted)."""
    return Path(str(importlib.resources.files("posturegen") / "data" / "proxies"))


def read_shipped(key: str) -> tuple[list[Sphere], dict[str, Any]] | None:
    """The shipped proxies fitted under ``key`` and their fit's report, None if none are."""
    path = shipped_dir() / f"{key}.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as z:
        joint, center, radius, excess = z["joint"], z["center"], z["radius"], z["excess"]
        report = json.loads(str(z["report"]))
    spheres = [
        Sphere(int(j), np.array(c, dtype=float), float(r), float(e))
        for j, c, r, e in zip(joint, center, radius, excess, strict=True)
    ]
    return spheres, report


def write_shipped(key: str, spheres: list[Sphere], report: dict[str, Any]) -> Path:
    """Write proxies to the package's ``data/proxies/<key>.npz`` (see :func:`shipped_dir`)."""
    path = shipped_dir() / f"{key}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        joint=np.array([s.joint_id for s in spheres], dtype=np.int32),  # (n,)
        center=np.array([s.center for s in spheres], dtype=float).reshape(-1, 3),  # (n, 3) [m]
        radius=np.array([s.radius for s in spheres], dtype=float),  # (n,) [m]
        excess=np.array([s.excess for s in spheres], dtype=float),  # (n,) [m]
        report=np.array(json.dumps(report)),
    )
    return path


def proxy_model(robot: Robot) -> ProxyModel:
    """The robot's proxies and candidate pairs (fitted once, cached on disk and in memory)."""
    cached = robot._proxy_model
    if cached is not None:
        return cached
    model = robot.model
    rule = pair_rule(model, robot.collision_model(), str(robot.srdf) if robot.srdf else None)
    key = _cache_key(robot)  # the meshes hashed once for both disk caches
    spheres, report = robot_spheres(robot, rule, key)
    joints = sorted({s.joint_id for s in spheres})
    pairs = [
        (a, b) for i, a in enumerate(joints) for b in joints[i + 1 :] if rule.reason(a, b) is None
    ]
    joint_pairs = np.array(pairs, dtype=int).reshape(-1, 2)
    clearance = _stored_clearance(key, robot, spheres, joint_pairs, rule.reference_q)
    pm = ProxyModel(spheres, joint_pairs, clearance, rule, limbs(model), report, chains(model), key)
    robot._proxy_model = pm
    return pm


def _stored_clearance(
    key: str, robot: Robot, spheres: list[Sphere], joint_pairs: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """:func:`reference_clearance`, cached on disk beside the proxies (a process's first
    collision call: Talos 0.1 s), keyed on the proxies' ``key`` (:func:`_cache_key`), their
    spheres, the pairs, q and this module's source."""
    h = hashlib.sha1(key.encode())
    for part in (joint_pairs.tobytes(), np.asarray(q, dtype=float).tobytes()):
        h.update(part)
    h.update(Path(__file__).read_bytes())
    h.update(np.array([[*s.center, s.radius, s.joint_id] for s in spheres]).tobytes())
    path = cache_dir() / f"clearance-{h.hexdigest()[:16]}.npy"
    try:
        stored = np.load(path)
        if stored.shape == (len(joint_pairs),) and np.all(np.isfinite(stored)):
            return stored
    except (OSError, ValueError):
        pass  # not stored yet, or a broken file: compute it
    clearance = reference_clearance(robot.model, spheres, joint_pairs, q)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, clearance)
    except OSError:
        pass  # a read-only cache: compute it next time
    return clearance


def reference_clearance(
    model: pin.Model, spheres: list[Sphere], joint_pairs: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """(P,) [m] the smallest distance between the proxies of each joint pair at posture q."""
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    of: dict[int, list[Sphere]] = {}
    for s in spheres:
        of.setdefault(s.joint_id, []).append(s)
    world = {
        j: (np.array([data.oMi[j].act(s.center) for s in sp]), np.array([s.radius for s in sp]))
        for j, sp in of.items()
    }
    out = np.empty(len(joint_pairs))
    for k, (a, b) in enumerate(joint_pairs):
        (ca, ra), (cb, rb) = world[int(a)], world[int(b)]
        out[k] = (np.linalg.norm(ca[:, None] - cb[None], axis=2) - ra[:, None] - rb).min()
    return out


def chains(model: pin.Model) -> tuple[tuple[int, ...], ...]:
    """Per joint id, the actuated coordinates (indices into qj) of the joints between it and
    the base, sorted (the free flyer is the base; the universe and the base have none)."""
    return tuple(
        tuple(sorted(model.joints[int(k)].idx_v - 6 for k in model.supports[j] if int(k) > 1))
        for j in range(model.njoints)
    )


def limbs(model: pin.Model) -> np.ndarray:
    """(njoints,) the limb of each joint: the first joint of its chain below the nearest
    branching of the kinematic tree (Talos: the pelvis, torso, head, each arm and each leg)."""
    children = np.bincount(np.asarray(model.parents[1:], dtype=int), minlength=model.njoints)
    out = np.arange(model.njoints)
    for j in range(2, model.njoints):
        parent = int(model.parents[j])
        out[j] = out[parent] if children[parent] < 2 and parent > 0 else j
    return out
