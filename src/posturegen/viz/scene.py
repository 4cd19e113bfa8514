"""World geometry of a stance's scene as triangles (surfaces, their solids, obstacles), what
a view of it must show, and the force arrows' scale."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .meshes import box_mesh
from .style import CONTACT_SURFACE_RGB, SCENE_RGB
from .views import StanceView, lift, transform


def clip_polygon(poly2d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """A convex polygon clipped to the rectangle [lo, hi] (shapely), None when empty."""
    from shapely.geometry import Polygon, box

    inter = Polygon(poly2d).intersection(box(lo[0], lo[1], hi[0], hi[1]))
    if inter.is_empty or inter.geom_type != "Polygon" or inter.area <= 0:
        return None
    return np.asarray(inter.exterior.coords)[:-1]


def local_rect(T: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rectangle of a surface's plane (its frame) that covers the world box [lo, hi]."""
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    local = (corners - T[:3, 3]) @ T[:3, :3]
    return local[:, :2].min(axis=0), local[:, :2].max(axis=0)


def surface_edges(
    T: np.ndarray, verts: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> list[np.ndarray]:
    """The pieces (2, 3) of a surface polygon's edges inside the world box [lo, hi]."""
    from shapely.geometry import LineString, box

    rlo, rhi = local_rect(T, lo, hi)
    window = box(rlo[0], rlo[1], rhi[0], rhi[1])
    edges = []
    for i in range(len(verts)):
        piece = LineString([verts[i], verts[(i + 1) % len(verts)]]).intersection(window)
        if piece.geom_type == "LineString" and piece.length > 0:
            edges.append(transform(T, lift(np.asarray(piece.coords))))
    return edges


BIG_SURFACE = 1.5  # [m]: a surface this wide (ground, wall) is drawn as a plane, a smaller
# one (step, rung, rail) as the solid under it, ``thickness`` deep


def scene_mesh(
    sv: StanceView, window: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World triangles of the scene: the surfaces (k, 3, 3) with their colours (k, 3) (in
    contact tinted red; a big surface clipped to the world box ``window`` when given, a small
    one with the sides of its solid, darker), and the obstacles' boxes (m, 3, 3)."""
    tris, cols = [], []
    in_contact = {c.surface for c in sv.contacts}
    for name, T, verts, thickness in sv.surfaces:
        rgb = np.array(CONTACT_SURFACE_RGB if name in in_contact else SCENE_RGB)
        small = float(np.ptp(verts, axis=0).max()) < BIG_SURFACE
        poly = verts if small or window is None else clip_polygon(verts, *local_rect(T, *window))
        if poly is None:
            continue
        top = lift(poly)
        fan = _fan(len(top))
        tris.append(transform(T, top[fan]))
        cols += [rgb] * len(fan)
        if small:
            bottom = top - [0, 0, thickness]
            tris.append(transform(T, bottom[fan[:, ::-1]]))
            cols += [rgb] * len(fan)
            for i in range(len(top)):
                j = (i + 1) % len(top)
                quad = np.array([top[i], top[j], bottom[j], bottom[i]])
                tris.append(transform(T, quad[[[0, 2, 1], [0, 3, 2]]]))
                cols += [0.8 * rgb] * 2
    boxes = []
    for _, size, T in sv.obstacles:
        V, F = box_mesh(size / 2)
        boxes.append(transform(T, V)[F])
    return (
        np.concatenate(tris) if tris else np.zeros((0, 3, 3)),
        np.array(cols, dtype=float).reshape(-1, 3),
        np.concatenate(boxes) if boxes else np.zeros((0, 3, 3)),
    )


def _fan(n: int) -> np.ndarray:
    """Triangles (n - 2, 3) of a fan over a convex polygon of n vertices."""
    return np.array([[0, i, i + 1] for i in range(1, n - 1)])


def content_points(sv: StanceView, robot: np.ndarray, scale: float) -> np.ndarray:
    """World points (k, 3) the view must show: the robot, every contact (polygons, ellipse,
    force arrows), the surfaces of the contacts that are not big, the targets."""
    pts = [robot.reshape(-1, 3)]
    for c in sv.contacts:
        pts.append(c.patch3d)
        if c.ellipse3d is not None:
            pts.append(c.ellipse_points(16))
        if len(c.points3d):
            pts += [c.points3d, c.points3d + scale * c.forces3d]
        if float(np.ptp(c.surface2d, axis=0).max()) < BIG_SURFACE:
            pts.append(transform(c.T_ws, lift(c.surface2d)))
    pts += [t[None] for _, t in sv.targets]
    return np.vstack(pts)


def bounds(sv: StanceView, robot: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The world box the viewer frames: :func:`content_points` and the obstacles near it."""
    allp = content_points(sv, robot, scale)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    centre = (lo + hi) / 2
    for _, size, T in sv.obstacles:
        if np.all(np.abs(T[:3, 3] - centre) < (hi - lo) / 2 + 0.6):
            V = transform(T, box_mesh(size / 2)[0])
            lo, hi = np.minimum(lo, V.min(axis=0)), np.maximum(hi, V.max(axis=0))
    return lo, hi


def force_scale(views: Sequence[StanceView]) -> float:
    """Metres of arrow per newton: the largest force point drawn 0.25 m long (at most the
    robot's weight drawn 1 m long)."""
    fmax = max(
        (
            float(np.linalg.norm(c.forces3d, axis=1).max())
            for sv in views
            for c in sv.contacts
            if len(c.forces3d)
        ),
        default=0.0,
    )
    weight = max(sv.weight for sv in views) if views else 1.0
    return min(0.25 / fmax if fmax > 0 else 0.0, 1.0 / max(weight, 1e-9))
