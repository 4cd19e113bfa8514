"""A robot's sphere proxies (:mod:`posturegen.proxy_fit`), cached, and its candidate
self-collision pairs: every pair of spheres of two joints that the pair rule
(:mod:`posturegen.pairs`) leaves checked.

Each pair of joints has a *clearance* [m]: how far apart its proxies are at the reference
posture. A pair whose proxies are closer there than the collision margin is held at least
that far apart instead of the margin (the reference itself stays feasible); one whose
proxies overlap there (their meshes do not: they would be unchecked) is held no deeper than
there, and the mesh check decides.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from . import pairs, proxy_fit, surface
from .pairs import PairRule, joint_pair, pair_rule
from .proxy_fit import PROXY_VERSION, Sphere, fit_robot
from .robot import Robot


def cache_dir() -> Path:
    """Where fitted proxies are cached: $POSTUREGEN_CACHE, else ~/.cache/posturegen."""
    root = os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen"
    return Path(root) / "proxies"


@dataclass
class ProxyModel:
    """Sphere proxies of a robot and its candidate self-collision pairs, sorted by pair of
    joints (the sphere pairs of each pair of joints are contiguous)."""

    spheres: list[Sphere]
    joint_pairs: np.ndarray  # (P, 2) candidate joint pairs (sorted ids)
    clearance: np.ndarray  # (P,) [m] their proxies' distance at the reference posture
    rule: PairRule
    # (njoints,) limb of each joint (see limbs()); None: every joint its own limb
    limb: np.ndarray | None = None
    report: dict[str, Any] = field(default_factory=dict)  # the fit's refinement report

    def __post_init__(self) -> None:
        self._joint = np.array([s.joint_id for s in self.spheres], dtype=int)  # (S,)
        self._local = np.array([s.center for s in self.spheres]).reshape(-1, 3)  # (S, 3)
        self._radii = np.array([s.radius for s in self.spheres])  # (S,)
        self._joints = np.unique(self._joint)  # the joints that carry spheres
        self._joint_list = [int(j) for j in self._joints]
        n = int(self._joint.max(initial=0)) + 1
        count = np.maximum(np.bincount(self._joint, minlength=n), 1)  # (n,)
        # broad phase: per joint, a sphere around its proxies, centred on the mean of their
        # centres (its world centre is the mean of theirs: a matrix product)
        self._mean = np.zeros((n, len(self.spheres)))
        self._mean[self._joint, np.arange(len(self.spheres))] = 1.0 / count[self._joint]
        mean = self._mean @ self._local
        self._bound_radius = np.zeros(n)
        np.maximum.at(
            self._bound_radius,
            self._joint,
            np.linalg.norm(self._local - mean[self._joint], axis=1) + self._radii,
        )
        self._link_a, self._link_b = self.joint_pairs[:, 0], self.joint_pairs[:, 1]
        self._pairs, self._pair_link, self._link_start = _sphere_pairs(
            self._joint, self.joint_pairs
        )
        self._pair_r = self._radii[self._pairs[:, 0]] + self._radii[self._pairs[:, 1]]

    @property
    def self_pairs(self) -> np.ndarray:
        """(n, 2) candidate sphere pairs (i, j), sorted by pair of joints."""
        return self._pairs

    @property
    def pair_link(self) -> np.ndarray:
        """(n,) index into ``joint_pairs`` of each candidate sphere pair."""
        return self._pair_link

    def pair_clearance(self, margin: float) -> np.ndarray:
        """(P,) [m] how far apart each candidate joint pair is held: min(margin, clearance)."""
        return np.minimum(margin, self.clearance)

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
    ) -> tuple[np.ndarray, np.ndarray]:
        """The candidate sphere pairs closer than ``slack`` (P,) [m] beyond their joint
        pair's own (``slack[l]``, per joint pair), among the joint pairs ``links`` (indices,
        default all), for sphere centres (S, 3) in world: (k,) their indices into
        ``self_pairs`` and (k,) their distances |c_i - c_j| - r_i - r_j [m]. Joint pairs whose
        bounding spheres are farther apart than their slack (a lower bound of every distance
        between their proxies) are not looked at."""
        b = self._mean @ centers  # the bounding spheres' world centres
        k = np.arange(len(self.joint_pairs)) if links is None else np.asarray(links)
        gap = np.linalg.norm(b[self._link_a[k]] - b[self._link_b[k]], axis=1)
        gap -= self._bound_radius[self._link_a[k]] + self._bound_radius[self._link_b[k]]
        k = k[gap < slack[k]]  # the joint pairs that pass
        first, count = self._link_start[k], self._link_start[k + 1] - self._link_start[k]
        # their sphere pairs: the runs first:first + count, gathered at once
        run_start = np.cumsum(count) - count
        pairs = np.arange(count.sum()) + np.repeat(first - run_start, count)
        u = centers[self._pairs[pairs, 0]] - centers[self._pairs[pairs, 1]]
        d = np.sqrt(np.einsum("ij,ij->i", u, u)) - self._pair_r[pairs]
        keep = d < slack[self._pair_link[pairs]]
        return pairs[keep], d[keep]

    def closest(self, pairs: np.ndarray, d: np.ndarray, per_link: int) -> np.ndarray:
        """The ``per_link`` closest of the sphere pairs ``pairs`` (indices, distances ``d``)
        of each joint pair: a subset of ``pairs``."""
        link = self._pair_link[pairs]
        order = np.lexsort((d, link))
        link = link[order]
        first = np.searchsorted(link, link)  # where each one's joint pair starts
        return pairs[order[np.arange(len(link)) - first < per_link]]

    def distances(self, centers: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """Distances |c_i - c_j| - r_i - r_j [m] of candidate sphere pairs (indices)."""
        u = centers[self._pairs[pairs, 0]] - centers[self._pairs[pairs, 1]]
        return np.sqrt(np.einsum("ij,ij->i", u, u)) - self._pair_r[pairs]

    def links_of(self, excluded: set[tuple[int, int]] | frozenset[tuple[int, int]]) -> np.ndarray:
        """Indices of the candidate joint pairs that are not ``excluded`` (sorted ids)."""
        return np.array(
            [i for i, (a, b) in enumerate(self.joint_pairs) if (int(a), int(b)) not in excluded],
            dtype=int,
        )

    @property
    def radii(self) -> np.ndarray:
        """(S,) radii [m]."""
        return self._radii

    @property
    def joint_ids(self) -> np.ndarray:
        """(S,) each sphere's joint."""
        return self._joint


def _sphere_pairs(
    joint: np.ndarray, joint_pairs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of spheres (i, j) of each joint pair (a, b), i of a and j of b: (n, 2),
    the index of each one's joint pair (n,), and (P + 1,) where each joint pair's run
    starts."""
    of = {int(j): np.flatnonzero(joint == j) for j in np.unique(joint)}
    blocks, links = [], []
    for k, (a, b) in enumerate(joint_pairs):
        ia, ib = of[int(a)], of[int(b)]
        blocks.append(np.c_[np.repeat(ia, len(ib)), np.tile(ib, len(ia))])
        links.append(np.full(len(ia) * len(ib), k))
    pairs = np.vstack(blocks).astype(np.int32) if blocks else np.zeros((0, 2), dtype=np.int32)
    link = np.concatenate(links) if links else np.zeros(0, dtype=int)
    start = np.searchsorted(link, np.arange(len(joint_pairs) + 1))
    return pairs, link, start


def _cache_key(robot: Robot) -> str:
    """A digest of what the fit depends on: the fitting code itself (its modules' sources:
    any change of a constant or a step fits anew), the URDF and the SRDF."""
    h = hashlib.sha1(f"v{PROXY_VERSION}".encode())
    for module in (proxy_fit, surface, pairs):
        h.update(Path(str(module.__file__)).read_bytes())
    for path in (robot.urdf, robot.srdf):
        if path is not None:
            h.update(Path(path).read_bytes())
    return h.hexdigest()[:16]


def robot_spheres(robot: Robot, rule: PairRule) -> tuple[list[Sphere], dict[str, Any]]:
    """The robot's proxies (:func:`posturegen.proxy_fit.fit_robot`), fitted once and cached
    on disk (:func:`cache_dir`); and the fit's report."""
    path = cache_dir() / f"{_cache_key(robot)}.json"
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


def proxy_model(robot: Robot) -> ProxyModel:
    """The robot's proxies and candidate pairs (fitted once, cached on disk and in memory)."""
    cached = robot._proxy_model
    if cached is not None:
        return cached
    model = robot.model
    rule = pair_rule(model, robot.collision_model(), str(robot.srdf) if robot.srdf else None)
    spheres, report = robot_spheres(robot, rule)
    joints = sorted({s.joint_id for s in spheres})
    pairs = [
        (a, b) for i, a in enumerate(joints) for b in joints[i + 1 :] if rule.reason(a, b) is None
    ]
    joint_pairs = np.array(pairs, dtype=int).reshape(-1, 2)
    clearance = reference_clearance(model, spheres, joint_pairs, rule.reference_q)
    pm = ProxyModel(spheres, joint_pairs, clearance, rule, limbs(model), report)
    robot._proxy_model = pm
    return pm


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


def limbs(model: pin.Model) -> np.ndarray:
    """(njoints,) the limb of each joint: the first joint of its chain below the nearest
    branching of the kinematic tree (Talos: the pelvis, torso, head, each arm and each leg)."""
    children = np.bincount(np.asarray(model.parents[1:], dtype=int), minlength=model.njoints)
    out = np.arange(model.njoints)
    for j in range(2, model.njoints):
        parent = int(model.parents[j])
        out[j] = out[parent] if children[parent] < 2 and parent > 0 else j
    return out


def joint_pair_index(pm: ProxyModel) -> dict[tuple[int, int], int]:
    """{(a, b): index into pm.joint_pairs}."""
    return {joint_pair(int(a), int(b)): k for k, (a, b) in enumerate(pm.joint_pairs)}
