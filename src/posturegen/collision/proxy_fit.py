"""Sphere proxies fitted to the surface of each joint's collision geometry, with a stated
bound on how far they stand outside it.

The construction: a sphere centred at a point c inside an object, c at depth d(c) below its
surface, radius r <= d(c) + ε, lies within ε of the ball B(c, d(c)), which is inside the
object: it stands at most ε = EXCESS outside (its *excess*). The joint's surface is refined
into triangles of edges <= EDGE; candidate centres are the centres of the largest empty
balls tangent to the surface at seed points (one per SEED_SPACING cell, along the
triangle's inward normal: for a surface that is not closed and consistently oriented, the
side where the generalized winding number is larger), and the points halfway to them.
Inside means a winding number above INSIDE once the mesh's holes are capped (robust to the
open meshes of HRP-2 and Romeo: a point in a half-closed cavity is not inside), and for a
mesh still open or inconsistently oriented once capped (25 of HRP-2's 31), also inside its
convex hull and no deeper than below it. A candidate covers a
triangle when its sphere contains the triangle's three corners (a ball is convex; a
tessellated primitive's sagitta added). A greedy set cover picks candidates, the one that
covers most uncovered triangles first; the triangles left seed candidates at half the
spacing (thin shells), and the last round adds spheres centred on the surface itself
(radius ε: they too stand at most ε outside). Every triangle is then inside a sphere
(tested): the proxies contain the whole surface. A sphere primitive is its own proxy.

Near regions (:func:`fit_joint`'s ``near``): where the surface faces another link closely at
the reference posture, a sphere may stand at most ε_near past it: along the normal ν of
each near point n, the sphere reaches (c - n)·ν + sqrt(r² - p²) beyond n (p the lateral
distance from n to c), so r² <= p² + (ε_near + |(c - n)·ν|)² at every near point.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .pairs import PairRule
from .surface import (
    Surface,
    depth,
    point_distances,
    refine,
    surface_of,
    winding_number,
)

EXCESS = 0.01  # [m] ε: how far a proxy may stand outside its mesh
EDGE = 0.015  # [m] longest edge of the triangles to cover (1 cm: 2x the time, 8 % fewer spheres)
MIN_EDGE = 0.004  # [m] longest edge of the triangles near a close link (refinement)
NEAR_SPACING = 0.002  # [m] the near points of a refinement: one per cell of this size
SEED_SPACING = 0.02  # [m] seeds of the candidate centres: one per cell of this size
TANGENT_STEPS = 12  # bisection steps of the largest empty tangent ball
FRACTIONS = (1.0, 0.5)  # candidate centres along each seed's normal, of that ball
INSIDE = 0.9  # a mesh candidate is inside when its |winding number| exceeds this
SEED_ROUNDS = 4  # rounds of seeding, each at half the spacing, from the triangles left


@dataclass(frozen=True)
class Sphere:
    """A proxy sphere: centre in its joint's frame [m], radius [m], and its excess [m] (how
    far at most it stands outside the geometry it was fitted to)."""

    joint_id: int
    center: np.ndarray  # (3,)
    radius: float
    excess: float = 0.0


@dataclass
class _Elements:
    """The triangles to cover, refined, of all the objects of one joint."""

    corners: np.ndarray  # (m, 3, 3)
    slack: np.ndarray  # (m,) [m] the sagitta of each triangle's object
    centre: np.ndarray  # (m, 3) centroid
    reach: np.ndarray  # (m,) farthest corner from the centroid, plus the slack
    normal: np.ndarray  # (m, 3) unit normal (right-hand rule; 0 for a degenerate triangle)
    source: np.ndarray  # (m,) index of the object

    @classmethod
    def of(
        cls, surfaces: list[Surface], edge: float, fine: tuple[np.ndarray, float] | None = None
    ) -> _Elements:
        """The surfaces refined to edges <= ``edge``; with ``fine`` = (points (k, 3),
        edge'), the triangles within 2.5 cm of those points further to edges <= edge'."""
        corners, slack, source = [], [], []
        for k, s in enumerate(surfaces):
            V, F = refine(s.vertices, s.triangles, edge)
            if fine is not None and len(fine[0]):
                mid = V[F].mean(axis=1)
                close = _near_any(mid, fine[0], 0.025 + edge)
                Vf, Ff = refine(V, F[close], fine[1])
                corners += [V[F[~close]], Vf[Ff]]
                slack += [np.full(int((~close).sum()) + len(Ff), s.sagitta)]
                source += [np.full(int((~close).sum()) + len(Ff), k)]
                continue
            corners.append(V[F])
            slack.append(np.full(len(F), s.sagitta))
            source.append(np.full(len(F), k))
        c = np.concatenate(corners)
        centre = c.mean(axis=1)
        reach = np.linalg.norm(c - centre[:, None], axis=2).max(axis=1)
        sl = np.concatenate(slack)
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        length = np.linalg.norm(n, axis=1)
        n = np.where(length[:, None] > 1e-12, n / np.maximum(length, 1e-300)[:, None], 0.0)
        return cls(c, sl, centre, reach + sl, n, np.concatenate(source))


def _near_any(points: np.ndarray, others: np.ndarray, within: float) -> np.ndarray:
    """(k,) mask: points (k, 3) within ``within`` [m] of any of ``others`` (m, 3)."""
    out = np.zeros(len(points), dtype=bool)
    for s in range(0, len(points), 512):
        d = np.linalg.norm(points[s : s + 512, None] - others[None], axis=2)
        out[s : s + 512] = d.min(axis=1, initial=np.inf) < within
    return out


@dataclass
class _Candidates:
    """Candidate centres (k, 3), their depth (k,), and their object index (k,)."""

    centre: np.ndarray
    depth: np.ndarray
    source: np.ndarray


def _candidates(surfaces: list[Surface], el: _Elements, seeds: np.ndarray) -> _Candidates:
    """Centres of the largest empty balls tangent to the surface at the centroids of the
    triangles ``seeds`` (indices into ``el``), and points on the way to them."""
    centres, depths, sources = [], [], []
    seeds = seeds[np.any(el.normal[seeds] != 0, axis=1)]
    for k, s in enumerate(surfaces):
        mine = seeds[el.source[seeds] == k]
        if not len(mine):
            continue
        p, n = el.centre[mine], el.normal[mine]
        if not s.mesh:
            n = -n  # primitives are tessellated with outward normals
        elif s.closed:  # inwards: where the winding number is larger
            w = np.abs(winding_number(np.vstack([p - 1e-3 * n, p + 1e-3 * n]), s.solid_corners))
            n = n * np.where(w[: len(p)] >= w[len(p) :], -1.0, 1.0)[:, None]
        else:  # not closed once capped: both ways, what is inside the hull stays
            p, n = np.vstack([p, p]), np.vstack([-n, n])
        cap = 0.5 * float(np.ptp(s.vertices, axis=0).max())
        t = _largest_empty(s, p, n, cap)
        c = np.vstack([p + (f * t)[:, None] * n for f in FRACTIONS])
        c = c[np.tile(t, len(FRACTIONS)) * np.repeat(FRACTIONS, len(t)) > 1e-4]
        d = depth(s, c)
        if s.mesh:  # inside: the winding number of the capped mesh
            d = np.where(np.abs(winding_number(c, s.solid_corners)) > INSIDE, d, 0.0)
        if s.mesh and not s.closed:  # and inside the convex hull, no deeper than below it
            d = np.minimum(d, -point_distances(s.hull, pin.SE3.Identity(), c, signed=True))
        good = d > 1e-4
        centres.append(c[good])
        depths.append(d[good])
        sources.append(np.full(int(good.sum()), k))
    if not centres:
        return _Candidates(np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=int))
    return _Candidates(np.vstack(centres), np.concatenate(depths), np.concatenate(sources))


def _thin(points: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of one point per cell of a grid of ``spacing`` [m]."""
    key = np.floor(points / spacing).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


def _largest_empty(s: Surface, p: np.ndarray, n: np.ndarray, cap: float) -> np.ndarray:
    """(k,) for each surface point p_i and unit direction n_i, the largest t <= cap such
    that the ball of radius t centred at p_i + t n_i holds no point of the surface (its
    centre is at depth >= t), by bisection."""
    lo, hi = np.zeros(len(p)), np.full(len(p), cap)
    full = depth(s, p + cap * n) >= cap * (1 - 1e-3)
    lo[full] = cap
    todo = ~full
    for _ in range(TANGENT_STEPS):
        if not todo.any():
            break
        mid = 0.5 * (lo[todo] + hi[todo])
        ok = depth(s, p[todo] + mid[:, None] * n[todo]) >= mid * (1 - 1e-3)
        idx = np.flatnonzero(todo)
        lo[idx[ok]] = mid[ok]
        hi[idx[~ok]] = mid[~ok]
    return lo


def _coverage(cand: _Candidates, radius: np.ndarray, el: _Elements) -> list[np.ndarray]:
    """Per candidate, the indices of the triangles its sphere contains (all three corners
    within the radius minus the triangle's slack). Candidates go by blocks of neighbours
    (sorted by 5 cm cells), each against the triangles in its box; the triangles' bounding
    spheres decide most, the corners the rest."""
    out: list[np.ndarray | None] = [None] * len(radius)
    cell = np.floor(cand.centre / 0.05).astype(np.int64)
    order = np.lexsort(cell.T[::-1])
    for s in range(0, len(order), 128):
        idx = order[s : s + 128]
        c, r = cand.centre[idx], radius[idx]
        grow = r.max() + el.reach.max()
        box = np.all(
            (el.centre >= c.min(axis=0) - grow) & (el.centre <= c.max(axis=0) + grow), axis=1
        )
        near = np.flatnonzero(box)
        gap = np.linalg.norm(el.centre[near][None] - c[:, None], axis=2)
        reach = el.reach[near]
        sure = gap + reach <= r[:, None]
        rows, cols = np.nonzero(~sure & (gap - reach <= r[:, None]))  # border: the corners
        far = np.linalg.norm(el.corners[near[cols]] - c[rows][:, None], axis=2).max(axis=1)
        inside = far + el.slack[near[cols]] <= r[rows]
        sure[rows[inside], cols[inside]] = True
        rows, cols = np.nonzero(sure)
        for k, part in zip(
            idx, np.split(near[cols], np.searchsorted(rows, np.arange(1, len(r)))), strict=True
        ):
            out[k] = part
    return out  # type: ignore[return-value]


def _greedy(covers: list[np.ndarray], uncovered: np.ndarray) -> tuple[list[int], np.ndarray]:
    """Lazy greedy set cover of the elements ``uncovered`` (mask): the candidate covering
    most uncovered elements first. Returns the chosen candidates and the mask of the
    elements left uncovered."""
    uncovered = uncovered.copy()
    heap = [(-len(c), k) for k, c in enumerate(covers) if len(c)]
    heapq.heapify(heap)
    chosen: list[int] = []
    while heap and uncovered.any():
        _, k = heapq.heappop(heap)
        gain = int(uncovered[covers[k]].sum())
        if gain == 0:
            continue
        if heap and gain < -heap[0][0]:
            heapq.heappush(heap, (-gain, k))  # stale count: put back with the true one
            continue
        chosen.append(k)
        uncovered[covers[k]] = False
    return chosen, uncovered


def fit_joint(
    joint_id: int,
    surfaces: list[Surface],
    excess: float = EXCESS,
    near: np.ndarray | None = None,
    near_excess: float = EXCESS,
) -> list[Sphere]:
    """Spheres that contain every point of the surfaces of one joint's objects, each at most
    ``excess`` outside them, and at most ``near_excess`` past the points ``near`` (k, 3)
    (see the module doc). A sphere primitive is its own proxy. Seeds every SEED_SPACING
    first; the triangles left uncovered seed more candidates (thin shells need them
    closer), at half the spacing each round; the last round adds spheres centred on the
    surface (radius ``excess``: they stand at most that outside). A triangle that none
    covers (none on the bundled robots) gets a sphere of its own around its corners."""
    balls = [s for s in surfaces if isinstance(s.geometry, coal.Sphere)]
    spheres = [
        Sphere(joint_id, np.asarray(s.placement.translation, dtype=float), float(s.geometry.radius))
        for s in balls
    ]
    surfaces = [s for s in surfaces if not isinstance(s.geometry, coal.Sphere)]
    if not surfaces:
        return spheres
    fine = None
    if near is not None and len(near):
        near = near[_thin(near[:, :3], NEAR_SPACING)]
        coarse = near[_thin(near[:, :3], 0.005), :3]  # enough to tell where to refine
        fine = (coarse, max(2 * near_excess, MIN_EDGE))
    el = _Elements.of(surfaces, EDGE, fine)
    left = np.ones(len(el.corners), dtype=bool)
    spacing = SEED_SPACING
    for round_ in range(SEED_ROUNDS):
        todo = np.flatnonzero(left)
        if not len(todo):
            break
        seeds = todo[_thin(el.centre[todo], spacing)]
        cand = _candidates(surfaces, el, seeds)
        if round_ == SEED_ROUNDS - 1:  # spheres on the surface itself
            cand = _Candidates(
                np.vstack([cand.centre, el.centre[seeds]]),
                np.concatenate([cand.depth, np.zeros(len(seeds))]),
                np.concatenate([cand.source, el.source[seeds]]),
            )
        radius = cand.depth + excess
        if near is not None and len(near):
            radius = np.minimum(radius, _near_radius(cand, near, near_excess))
        covers = [c[left[c]] for c in _coverage(cand, radius, el)]
        chosen, left = _greedy(covers, left)
        spheres += [
            Sphere(joint_id, cand.centre[k], float(radius[k]), float(radius[k] - cand.depth[k]))
            for k in chosen
        ]
        spacing /= 2
    for t in np.flatnonzero(left):
        r = float(el.reach[t]) + 1e-9
        spheres.append(Sphere(joint_id, el.centre[t], r, r))
    return spheres


def _near_radius(cand: _Candidates, near: np.ndarray, eps: float) -> np.ndarray:
    """(k,) the largest radius of each candidate that reaches at most ``eps`` past every
    near point: ``near`` (m, 6) holds points and unit normals (see the module doc)."""
    out = np.empty(len(cand.depth))
    for s in range(0, len(out), 256):
        u = cand.centre[s : s + 256, None] - near[None, :, :3]  # (k, m, 3) from n to c
        along = np.abs(np.einsum("kmi,mi->km", u, near[:, 3:]))
        lateral2 = np.maximum(np.einsum("kmi,kmi->km", u, u) - along**2, 0.0)
        r = np.sqrt(lateral2 + (eps + along) ** 2).min(axis=1)
        out[s : s + 256] = np.maximum(r, cand.depth[s : s + 256])
    return out


# --------------------------------------------------------------------------- a robot's proxies
PROXY_VERSION = 6
REFERENCE_MARGIN = 0.01  # [m] the clearance the proxies of a pair aim for at the reference
MIN_REFINE_GAP = 0.004  # [m] pairs whose meshes are closer at the reference are not refined
MIN_NEAR_EXCESS = 0.002  # [m] the smallest excess of a refined region


def fit_robot(
    model: pin.Model, geometry: pin.GeometryModel, rule: PairRule
) -> tuple[list[Sphere], dict[str, Any]]:
    """The proxies of every joint that carries geometry (:func:`fit_joint`), refined where
    two links' proxies are closer at the reference posture than min(REFERENCE_MARGIN, half
    their meshes' distance) and the meshes at least MIN_REFINE_GAP apart: each of the two
    joints is fitted again with the excess of its surface that faces the other (within half
    that distance + ε + ε_near of it: where an unrefined sphere could reach) at ε_near, a
    quarter of the meshes' distance (at least MIN_NEAR_EXCESS). Returns the spheres and a
    report: every checked pair whose proxies are closer than REFERENCE_MARGIN at the
    reference, with its mesh and proxy distances, and the refined joints' near excess."""
    surfaces: dict[int, list[Surface]] = {}
    for obj in geometry.geometryObjects:
        surfaces.setdefault(int(obj.parentJoint), []).append(surface_of(obj))
    fitted = {j: fit_joint(j, s) for j, s in surfaces.items()}
    data = model.createData()
    pin.forwardKinematics(model, data, rule.reference_q)
    gdata = geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, gdata)
    near_excess: dict[int, float] = {}
    near: dict[int, list[np.ndarray]] = {}  # per joint: its points that face a close link
    for (a, b), (mesh_gap, _) in _tight_pairs(model, data, geometry, gdata, rule, fitted).items():
        if mesh_gap < MIN_REFINE_GAP:
            continue  # closer than spheres can follow: held at its reference clearance
        eps = float(np.clip(mesh_gap / 4, MIN_NEAR_EXCESS, EXCESS))
        within = mesh_gap / 2 + EXCESS + eps  # where an unrefined sphere could reach it
        for j, other in ((a, b), (b, a)):
            near_excess[j] = min(near_excess.get(j, EXCESS), eps)
            near.setdefault(j, []).append(
                _facing(surfaces[j], data.oMi[j], geometry, gdata, other, within)
            )
    for j, eps in near_excess.items():
        fitted[j] = fit_joint(j, surfaces[j], EXCESS, np.vstack(near[j]), eps)
    final = _tight_pairs(model, data, geometry, gdata, rule, fitted, everything=True)
    report = {
        "close": [
            {"pair": [model.names[a], model.names[b]], "mesh": g, "proxies": p}
            for (a, b), (g, p) in sorted(final.items())
        ],
        "near_excess": {model.names[j]: e for j, e in sorted(near_excess.items())},
    }
    return [s for j in sorted(fitted) for s in fitted[j]], report


def _tight_pairs(
    model: pin.Model,
    data: pin.Data,
    geometry: pin.GeometryModel,
    gdata: pin.GeometryData,
    rule: PairRule,
    fitted: dict[int, list[Sphere]],
    everything: bool = False,
) -> dict[tuple[int, int], tuple[float, float]]:
    """Checked joint pairs whose proxies are closer than REFERENCE_MARGIN at the reference
    posture (``data``, ``gdata``), with (mesh distance, proxy distance) [m]; unless
    ``everything``, only those closer than half their meshes' distance too."""
    world = {
        j: (np.array([data.oMi[j].act(s.center) for s in sp]), np.array([s.radius for s in sp]))
        for j, sp in fitted.items()
    }
    joints = sorted(world)
    out = {}
    for i, a in enumerate(joints):
        for b in joints[i + 1 :]:
            if rule.reason(a, b) is not None:
                continue
            (ca, ra), (cb, rb) = world[a], world[b]
            proxy = float((np.linalg.norm(ca[:, None] - cb[None], axis=2) - ra[:, None] - rb).min())
            if proxy >= REFERENCE_MARGIN:
                continue
            mesh = _mesh_distance(geometry, gdata, a, b)
            if everything or proxy < min(REFERENCE_MARGIN, mesh / 2):
                out[(a, b)] = (mesh, proxy)
    return out


def _mesh_distance(geometry: pin.GeometryModel, gdata: pin.GeometryData, a: int, b: int) -> float:
    """The distance [m] between the meshes of joints a and b (placements in ``gdata``)."""
    objs = geometry.geometryObjects
    out = np.inf
    for i, oi in enumerate(objs):
        for j, oj in enumerate(objs):
            if int(oi.parentJoint) != a or int(oj.parentJoint) != b:
                continue
            Mi, Mj = gdata.oMg[i], gdata.oMg[j]
            d = coal.distance(
                oi.geometry,
                coal.Transform3s(Mi.rotation, Mi.translation),
                oj.geometry,
                coal.Transform3s(Mj.rotation, Mj.translation),
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )
            out = min(out, float(d))
    return out


def _facing(
    surfaces: list[Surface],
    T_world_joint: pin.SE3,
    geometry: pin.GeometryModel,
    gdata: pin.GeometryData,
    other: int,
    within: float,
) -> np.ndarray:
    """(k, 6) points of a joint's refined surfaces and their unit normals (its frame),
    those closer than ``within`` [m] to the meshes of joint ``other`` (placements in
    ``gdata``)."""
    el = _Elements.of(surfaces, EDGE)
    pts = np.vstack([el.centre, el.corners.reshape(-1, 3)])
    normals = np.vstack([el.normal, np.repeat(el.normal, 3, axis=0)])
    world = pts @ np.asarray(T_world_joint.rotation).T + T_world_joint.translation
    d = np.full(len(pts), np.inf)
    for k, obj in enumerate(geometry.geometryObjects):
        if int(obj.parentJoint) == other:
            d = np.minimum(d, point_distances(obj.geometry, gdata.oMg[k], world))
    keep = (d < within) & np.any(normals != 0, axis=1)
    return np.c_[pts[keep], normals[keep]]
