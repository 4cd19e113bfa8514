"""Collision geometry as triangle surfaces: tessellation, refinement, depth and winding number.

A :class:`Surface` is one collision object's boundary as triangles in its parent joint's
frame: a mesh's own triangles, or a primitive (box, sphere, cylinder, capsule, cone)
tessellated with its vertices on the true surface; ``sagitta`` [m] bounds how far the true
surface lies from the flat triangles (0 for meshes and boxes).
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..errors import ModelError

ROUND_SIDES = 48  # polygon sides of a tessellated circle (sagitta 0.2 % of the radius)
SPHERE_LEVEL = 3  # icosphere subdivisions of a tessellated sphere (1,280 triangles)


@dataclass(frozen=True)
class Surface:
    """One collision object's triangles in its parent joint's frame."""

    name: str
    joint_id: int
    vertices: np.ndarray  # (n, 3) [m]
    triangles: np.ndarray  # (m, 3) vertex indices
    sagitta: float  # [m] the true surface is within this of the triangles
    mesh: bool  # depth from its triangles (a mesh, a cone), else a primitive's exact depth
    geometry: coal.CollisionGeometry
    placement: pin.SE3  # the object in its joint's frame
    # a mesh's holes closed (see :func:`capped`), in the joint's frame: what is inside
    solid: coal.CollisionGeometry | None = None
    solid_corners: np.ndarray | None = None  # (m', 3, 3) its triangles
    closed: bool = True  # a primitive, or a mesh closed and consistently oriented once capped
    hull: coal.CollisionGeometry | None = None  # a mesh's convex hull, in the joint's frame

    def corners(self) -> np.ndarray:
        """(m, 3, 3) the triangles' vertices."""
        return self.vertices[self.triangles]


def surface_of(obj: pin.GeometryObject) -> Surface:
    """The triangle surface of a collision object, in its parent joint's frame."""
    g = obj.geometry
    if isinstance(g, coal.BVHModelBase):
        V = np.asarray(g.vertices(), dtype=float)
        F = np.array([[t[0], t[1], t[2]] for t in map(g.tri_indices, range(g.num_tris))])
        sag, mesh = 0.0, True
    elif isinstance(g, coal.Box):
        V, F = _box(np.asarray(g.halfSide, dtype=float))
        sag, mesh = 0.0, False
    elif isinstance(g, coal.Sphere):
        V, F = icosphere(SPHERE_LEVEL)
        V = V * g.radius
        sag, mesh = g.radius * (1.0 - _icosphere_cos(SPHERE_LEVEL)), False
    elif isinstance(g, coal.Cylinder | coal.Capsule | coal.Cone):
        V, F = _round(g)
        # a cone's depth is its tessellation's (inscribed: no deeper than the true one)
        sag, mesh = _round_sagitta(g), isinstance(g, coal.Cone)
    else:
        raise ModelError(f"collision geometry '{obj.name}' has unsupported type {type(g).__name__}")
    M = obj.placement
    world = V @ np.asarray(M.rotation).T + np.asarray(M.translation)
    F = np.asarray(F, dtype=int).reshape(-1, 3)
    solid, solid_corners = None, None
    if mesh:
        Vc, Fc = capped(world, F)
        solid = coal.BVHModelOBBRSS()
        solid.beginModel(len(Fc), len(Vc))
        solid.addVertices(Vc)
        solid.addTriangles(Fc.astype(np.int64))
        solid.endModel()
        solid_corners = Vc[Fc]
        closed = oriented_closed(Fc)
        hull = None
        if not closed:
            solid.buildConvexHull(False, "")  # without qhull: its points' support function
            hull = solid.convex
    return Surface(
        obj.name, int(obj.parentJoint), world, F, float(sag), mesh, g, pin.SE3(M), solid,
        solid_corners, closed if mesh else True, hull if mesh else None,
    )  # fmt: skip


def capped(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh (V, F) with its holes closed: vertices merged by position (to 0.1 µm), each
    loop of boundary edges (edges of one triangle) closed by a fan from its centroid, the
    fan oriented like the triangles around it. The meshes of HRP-2 and Romeo are open (up to
    1,146 boundary edges); a ball inside one could reach out through a hole."""
    _, first, inverse = np.unique(
        np.round(V / 1e-7).astype(np.int64), axis=0, return_index=True, return_inverse=True
    )
    V = V[first]
    F = inverse.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])]
    directed = np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, index, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    boundary = directed[index[counts == 1]]  # (b, 2) as their triangle runs them
    out: dict[int, list[int]] = {}  # the cap runs each boundary edge backwards
    for a, b in boundary:
        out.setdefault(int(b), []).append(int(a))
    extra_v: list[np.ndarray] = []
    extra_f: list[list[int]] = []
    while out:
        start = next(iter(out))
        loop = [start]
        while loop[-1] in out:
            step = out[loop[-1]].pop()
            if not out[loop[-1]]:
                del out[loop[-1]]
            if step in loop:  # a closed loop (at a pinch vertex: the part since its visit)
                ring = loop[loop.index(step) :]
                del loop[loop.index(step) + 1 :]
                if len(ring) >= 3:
                    centre = len(V) + len(extra_v)
                    extra_v.append(V[ring].mean(axis=0))
                    pairs = zip(ring, ring[1:] + ring[:1], strict=True)
                    extra_f += [[a, b, centre] for a, b in pairs]
                continue
            loop.append(step)
    if not extra_v:
        return V, F
    return np.vstack([V, extra_v]), np.vstack([F, np.array(extra_f, dtype=int)])


def _box(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 8 corners and 12 outward triangles of a box of half sizes ``half``."""
    V = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    F = np.array(
        [
            [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
            [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
        ]
    )  # fmt: skip
    return V, F


def _round(g: coal.ShapeBase) -> tuple[np.ndarray, np.ndarray]:
    """A cylinder, cone or capsule along z as a surface of revolution: its profile (radius,
    z) from the bottom pole to the top one (a capsule's half circles in ROUND_SIDES / 4
    steps), each point revolved into a ROUND_SIDES-gon (the poles stay points)."""
    r, h = float(g.radius), float(g.halfLength)
    if isinstance(g, coal.Capsule):
        phi = np.linspace(-np.pi / 2, 0.0, ROUND_SIDES // 4 + 1)
        low = np.c_[r * np.cos(phi), -h + r * np.sin(phi)]
        profile = np.vstack([low, (low * [1, -1])[::-1]])
    elif isinstance(g, coal.Cone):
        profile = np.array([[0.0, -h], [r, -h], [0.0, h]])
    else:
        profile = np.array([[0.0, -h], [r, -h], [r, h], [0.0, h]])
    n = ROUND_SIDES
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rings = [
        np.array([[0.0, 0.0, z]])
        if rho < 1e-12
        else np.c_[rho * np.cos(t), rho * np.sin(t), np.full(n, z)]
        for rho, z in profile
    ]
    start = np.cumsum([0] + [len(x) for x in rings])
    faces = []
    i = np.arange(n)
    j = (i + 1) % n
    for k in range(len(rings) - 1):
        a, b = start[k], start[k + 1]
        if len(rings[k]) == 1:
            faces.append(np.c_[np.full(n, a), b + j, b + i])
        elif len(rings[k + 1]) == 1:
            faces.append(np.c_[a + i, a + j, np.full(n, b)])
        else:
            faces += [np.c_[a + i, a + j, b + j], np.c_[a + i, b + j, b + i]]
    return np.vstack(rings), np.vstack(faces)


def _round_sagitta(g: coal.ShapeBase) -> float:
    """How far [m] the true surface of :func:`_round`'s shape lies from its triangles."""
    sag = g.radius * (1.0 - np.cos(np.pi / ROUND_SIDES))
    if isinstance(g, coal.Capsule):  # the half circles' chords, then the ring around them
        sag += g.radius * (1.0 - np.cos(np.pi / (ROUND_SIDES // 2)))
    return float(sag)


def icosphere(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: (n, 3) vertices on the sphere, (m, 3) outward triangles."""
    p = (1 + 5**0.5) / 2
    V = np.array(
        [
            [-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
            [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1],
        ],
        dtype=float,
    )  # fmt: skip
    F = np.array(
        [
            [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
            [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
            [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
        ]
    )  # fmt: skip
    V /= np.linalg.norm(V, axis=1)[:, None]
    for _ in range(level):
        V, F = _split_all(V, F)
        V /= np.linalg.norm(V, axis=1)[:, None]
    return V, F


def _icosphere_cos(level: int) -> float:
    """cos of the largest angle between a unit icosphere's triangle centroid and its
    vertices: the flat triangles lie at least this far from the centre."""
    V, F = icosphere(level)
    c = V[F].mean(axis=1)
    c /= np.linalg.norm(c, axis=1)[:, None]
    return float(np.einsum("ij,ikj->ik", c, V[F]).min())


def _split_all(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle into four at its edges' midpoints (shared midpoints merged)."""
    edges = np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = len(V) + inverse.reshape(3, -1)  # (3, m): midpoint of edges 01, 12, 20
    V = np.vstack([V, 0.5 * (V[unique[:, 0]] + V[unique[:, 1]])])
    a, b, c = F.T
    ab, bc, ca = mid
    F = np.vstack([np.c_[a, ab, ca], np.c_[ab, b, bc], np.c_[ca, bc, c], np.c_[ab, bc, ca]])
    return V, F


def refine(V: np.ndarray, F: np.ndarray, edge: float) -> tuple[np.ndarray, np.ndarray]:
    """Longest-edge bisection until no edge is longer than ``edge`` [m]: (n', 3) vertices
    (the unused ones dropped) and (m', 3) triangles covering the same surface."""
    V = np.asarray(V, dtype=float)
    F = np.asarray(F, dtype=int).reshape(-1, 3)
    if not len(F):
        return V[:0], F
    done = []
    while len(F):
        e = np.stack([np.linalg.norm(V[F[:, (a + 1) % 3]] - V[F[:, a]], axis=1) for a in range(3)])
        k = e.argmax(axis=0)
        long = e[k, np.arange(len(F))] > edge
        done.append(F[~long])
        F, k = F[long], k[long]
        if not len(F):
            break
        r = np.stack([F[np.arange(len(F)), (k + i) % 3] for i in range(3)], axis=1)  # 01 longest
        key = np.sort(r[:, :2], axis=1)
        unique, inverse = np.unique(key, axis=0, return_inverse=True)
        m = len(V) + inverse.ravel()
        V = np.vstack([V, 0.5 * (V[unique[:, 0]] + V[unique[:, 1]])])
        F = np.vstack([np.c_[r[:, 0], m, r[:, 2]], np.c_[m, r[:, 1], r[:, 2]]])
    F = np.vstack(done)
    used, inverse = np.unique(F, return_inverse=True)
    return V[used], inverse.reshape(-1, 3)


# a point as a coal shape: the distance from it to a geometry is the point's distance
_POINT = coal.Sphere(1e-9)
_REQUEST = coal.DistanceRequest()
_SIGNED = coal.DistanceRequest()
_SIGNED.enable_signed_distance = True


def depth(surface: Surface, points: np.ndarray) -> np.ndarray:
    """(k,) how deep [m] each joint-frame point (k, 3) lies below the object's surface: a
    primitive's signed depth (< 0 outside), a mesh's unsigned distance to its triangles and
    the caps of its holes (the caller knows the point is inside, see :func:`winding_number`)."""
    if surface.solid is not None:  # a mesh: the distance to its triangles and hole caps
        return np.abs(point_distances(surface.solid, pin.SE3.Identity(), points))
    inv = surface.placement.inverse()
    local = np.asarray(points, dtype=float) @ np.asarray(inv.rotation).T + inv.translation
    return primitive_depth(surface.geometry, local)


def primitive_depth(g: coal.ShapeBase, p: np.ndarray) -> np.ndarray:
    """(k,) the signed depth [m] of points p (k, 3) in a primitive's frame: the distance to
    its surface, < 0 outside (a lower bound there), exactly (coal's EPA is not: 0.125 instead
    of 0.025 for a point 2.5 cm under a cylinder's cap)."""
    if isinstance(g, coal.Box):
        h = np.asarray(g.halfSide, dtype=float)
        inside = (h - np.abs(p)).min(axis=1)
        return np.where(inside >= 0, inside, -np.linalg.norm(np.maximum(np.abs(p) - h, 0), axis=1))
    if isinstance(g, coal.Sphere):
        return g.radius - np.linalg.norm(p, axis=1)
    rho, z, h, r = np.linalg.norm(p[:, :2], axis=1), p[:, 2], g.halfLength, g.radius
    if isinstance(g, coal.Capsule):
        return r - np.hypot(rho, np.maximum(np.abs(z) - h, 0))
    if isinstance(g, coal.Cylinder):
        side, cap = r - rho, h - np.abs(z)
        outside = -np.hypot(np.maximum(-side, 0), np.maximum(-cap, 0))
        return np.where((side >= 0) & (cap >= 0), np.minimum(side, cap), outside)
    raise ModelError(f"no depth for a {type(g).__name__}")


WINDING_CELL = 0.02  # [m] clusters of triangles seen as dipoles from afar (winding_number)
WINDING_EXACT = 2000  # up to this many triangles, every one is summed exactly


def winding_number(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(k,) generalized winding numbers of points (k, 3) w.r.t. triangles (m, 3, 3): the
    sum of their signed solid angles / 4π (Van Oosterom-Strackee): ±1 inside a closed
    surface, 0 outside, in between near the holes of an open one. Beyond WINDING_EXACT
    triangles, points go by batches of neighbours: the triangles of the WINDING_CELL cells
    within 3√3 cells of a batch exactly, the farther cells as dipoles, their vector area N
    at their centroid x: Ω ≈ N·(x - q)/|x - q|³ (a 19,000-triangle mesh of G1: 40 s -> 3 s;
    off by a few 0.01 at most)."""
    points = np.asarray(points, dtype=float)
    if len(corners) <= WINDING_EXACT:
        return _solid_angles(points, corners) / (4 * np.pi)
    cell = np.floor(corners.mean(axis=1) / WINDING_CELL).astype(np.int64)
    _, owner = np.unique(cell, axis=0, return_inverse=True)
    owner = owner.ravel()
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = 0.5 * np.cross(b - a, c - a)  # (m, 3) vector areas
    n_cells = int(owner.max()) + 1
    N = np.zeros((n_cells, 3))
    np.add.at(N, owner, area)
    weight = np.linalg.norm(area, axis=1) + 1e-30
    X = np.zeros((n_cells, 3))
    np.add.at(X, owner, corners.mean(axis=1) * weight[:, None])
    X /= np.maximum(np.bincount(owner, weights=weight, minlength=n_cells), 1e-30)[:, None]
    out = np.zeros(len(points))
    order = np.lexsort(np.floor(points / (4 * WINDING_CELL)).astype(np.int64).T[::-1])
    near_reach = 3 * np.sqrt(3) * WINDING_CELL
    for s in range(0, len(order), 64):
        idx = order[s : s + 64]
        q = points[idx]
        lo, hi = q.min(axis=0) - near_reach, q.max(axis=0) + near_reach
        near = np.all((X >= lo) & (X <= hi), axis=1)
        exact = near[owner]
        omega = _solid_angles(q, corners[exact])
        u = X[~near][None] - q[:, None]  # (k, far, 3)
        r3 = np.linalg.norm(u, axis=2) ** 3
        omega += np.einsum("kfi,fi->k", u / r3[:, :, None], N[~near])
        out[idx] = omega / (4 * np.pi)
    return out


def _solid_angles(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(k,) the sum of the signed solid angles [sr] of triangles (m, 3, 3) seen from each
    point (k, 3) (Van Oosterom-Strackee)."""
    out = np.zeros(len(points))
    A, B, C = (np.ascontiguousarray(corners[:, i, :].T) for i in range(3))  # (3, m) each
    for s in range(0, len(points), 64):
        q = points[s : s + 64, :, None]  # (k, 3, 1)
        a, b, c = A - q, B - q, C - q  # (k, 3, m)
        la, lb, lc = (np.sqrt((x * x).sum(axis=1)) for x in (a, b, c))
        bc = np.stack(
            [
                b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1],
                b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2],
                b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0],
            ],
            axis=1,
        )
        det = (a * bc).sum(axis=1)
        den = la * lb * lc + (a * b).sum(axis=1) * lc + (b * c).sum(axis=1) * la
        den += (c * a).sum(axis=1) * lb
        out[s : s + 64] = 2 * np.arctan2(det, den).sum(axis=1)
    return out


def oriented_closed(F: np.ndarray) -> bool:
    """Every edge of the triangles (m, 3) is shared by exactly two of them, in opposite
    directions: a closed, consistently oriented surface."""
    directed = np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) != len(directed):
        return False
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Σ a·(b × c)/6 over the triangles [m³]: the enclosed volume, > 0 when their normals
    (right-hand rule) point outwards."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def hull_points(obj: pin.GeometryObject) -> np.ndarray:
    """Points (k, 3) in the parent joint's frame whose convex hull contains the geometry
    (a circle's polygon circumscribed, a sphere's octahedron scaled by √3)."""
    g = obj.geometry
    if isinstance(g, coal.BVHModelBase):
        local = np.asarray(g.vertices(), dtype=float)
    elif isinstance(g, coal.Box):
        local = _box(np.asarray(g.halfSide, dtype=float))[0]
    elif isinstance(g, coal.Cylinder | coal.Capsule | coal.Cone):
        r = g.radius / np.cos(np.pi / 16)
        t = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        ring = np.c_[r * np.cos(t), r * np.sin(t)]
        z = g.halfLength + (g.radius if isinstance(g, coal.Capsule) else 0.0)
        local = np.vstack([np.c_[ring, np.full(len(t), -z)], np.c_[ring, np.full(len(t), z)]])
    elif isinstance(g, coal.Sphere):
        local = np.vstack([np.eye(3), -np.eye(3)]) * g.radius * np.sqrt(3)
    else:
        raise ModelError(f"collision geometry '{obj.name}' has unsupported type {type(g).__name__}")
    M = obj.placement
    return local @ np.asarray(M.rotation).T + np.asarray(M.translation)


def convex_shape(obj: pin.GeometryObject) -> coal.CollisionGeometry:
    """The object as a convex coal shape: a primitive itself, a mesh's convex hull (the
    points of its vertices; GJK and EPA need only their support function)."""
    g = obj.geometry
    if not isinstance(g, coal.BVHModelBase):
        return g
    if g.convex is None:
        g.buildConvexHull(False, "")  # without qhull: the vertices, no hull faces
    return g.convex


def penetration_depth(
    a: coal.CollisionGeometry, T_a: pin.SE3, b: coal.CollisionGeometry, T_b: pin.SE3
) -> float:
    """How deep [m] two convex shapes interpenetrate (coal's EPA; 0 when apart): the
    smallest translation that separates them."""
    result = coal.DistanceResult()
    d = coal.distance(
        a,
        coal.Transform3s(T_a.rotation, T_a.translation),
        b,
        coal.Transform3s(T_b.rotation, T_b.translation),
        _SIGNED,
        result,
    )
    return max(-float(d), 0.0)


def point_distances(
    geometry: coal.CollisionGeometry,
    T_world_geometry: pin.SE3,
    points: np.ndarray,
    signed: bool = False,
) -> np.ndarray:
    """(k,) distances [m] from world points (k, 3) to a placed geometry (coal; a point
    inside a primitive is at a negative distance, inside a mesh at its distance to the
    triangles; inside a convex shape at a negative one when ``signed``)."""
    inv = T_world_geometry.inverse()
    local = np.asarray(points, dtype=float) @ np.asarray(inv.rotation).T + inv.translation
    out = np.empty(len(local))
    origin, result = coal.Transform3s(), coal.DistanceResult()
    for i, p in enumerate(local):
        result.clear()
        out[i] = coal.distance(
            _POINT,
            coal.Transform3s(np.eye(3), p),
            geometry,
            origin,
            _SIGNED if signed else _REQUEST,
            result,
        )
    return out
