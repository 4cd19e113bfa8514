"""Where things are for the heuristic: each surface as a polygon in space, the point of a
surface nearest a goal spot within a patch's reach, and the goal spot of every patch."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import shapely

from ..scene import Scene, Surface
from .goal import Goal

GRID = 9  # candidate points per side of a surface's bounding box
# [m] candidate points this far inside a surface, at most 90 % of its inradius: on a step or a
# rung, its middle line (a target at the back edge of a stair step put Talos' toes against the
# next riser and IPOPT found the touch infeasible)
EDGE_MARGIN = 0.1
EDGE_SHARE = 0.9


@dataclass(frozen=True)
class Region:
    """A surface's polygon in its plane, for distances and candidate points."""

    surface: Surface
    polygon: shapely.Polygon  # (surface frame, 2-D)

    @classmethod
    def of(cls, surface: Surface) -> Region:
        return cls(surface, shapely.Polygon(surface.polygon.vertices))

    def to_local(self, p_world: np.ndarray) -> np.ndarray:
        """World point (3,) -> surface frame (3,) [m]."""
        T = self.surface.T_world_surface
        return np.asarray(T.rotation.T @ (p_world - T.translation))

    def distance(self, p_world: np.ndarray) -> float:
        """Euclidean distance [m] from a world point to the surface polygon."""
        local = self.to_local(p_world)
        flat = shapely.Point(local[0], local[1])
        d2 = self.polygon.distance(flat)
        return float(np.hypot(d2, local[2]))

    def centre(self) -> np.ndarray:
        """The polygon's centroid, world (3,) [m]."""
        c = self.polygon.centroid
        return self.surface.to_world(np.array([[c.x, c.y]]))[0]

    def candidates(self) -> np.ndarray:
        """(k, 3) world points on a grid inside the polygon, EDGE_MARGIN from its edges (at
        most EDGE_SHARE of its inradius)."""
        inradius = float(shapely.maximum_inscribed_circle(self.polygon).length)
        inner = self.polygon.buffer(-min(EDGE_MARGIN, EDGE_SHARE * inradius))
        if inner.is_empty:
            inner = self.polygon
        x0, y0, x1, y1 = inner.bounds
        xs, ys = np.meshgrid(np.linspace(x0, x1, GRID), np.linspace(y0, y1, GRID))
        pts = np.column_stack([xs.ravel(), ys.ravel()])
        keep = shapely.contains_xy(inner, pts[:, 0], pts[:, 1]) | shapely.intersects_xy(
            inner, pts[:, 0], pts[:, 1]
        )
        c = inner.centroid
        pts = np.vstack([pts[keep], [[c.x, c.y]]])
        return self.surface.to_world(pts)


def regions(scene: Scene) -> dict[str, Region]:
    """Every surface of the scene as a Region."""
    return {name: Region.of(s) for name, s in scene.surfaces.items()}


def pick_target(
    region: Region, spot: np.ndarray, anchors: list[np.ndarray], reach: float
) -> np.ndarray | None:
    """The candidate point of ``region`` nearest the goal ``spot`` (3,) among those within
    ``reach`` [m] of an anchor (a sole in contact); None when none is."""
    pts = region.candidates()
    if anchors:
        d = np.min([np.linalg.norm(pts - a, axis=1) for a in anchors], axis=0)
        pts = pts[d <= reach]
    if len(pts) == 0:
        return None
    return np.array(pts[int(np.argmin(np.linalg.norm(pts - spot, axis=1)))])


def goal_spots(
    goal: Goal,
    areas: Mapping[str, Region],
    start: Mapping[str, np.ndarray],
    frame_start: np.ndarray | None,
) -> dict[str, np.ndarray]:
    """Where each patch heads (3,) [m]: a goal contact's patch to its surface's centre, moved
    sideways by its offset from the start stance's middle; any other patch keeps its offset
    from the goal patches (or from the goal frame) at the start."""
    names = list(start)
    if goal.contacts:
        mid = np.mean([start[p] for p, _ in goal.contacts], axis=0)
        spots = {}
        for p, s in goal.contacts:
            spot = areas[s].centre().copy()
            spot[1] += start[p][1] - mid[1]
            spots[p] = spot
        centre = np.mean(list(spots.values()), axis=0)
        for p in names:
            if p not in spots:
                spots[p] = centre + (start[p] - mid)
        return spots
    point = np.array(goal.point)
    ref = frame_start if frame_start is not None else np.mean(list(start.values()), axis=0)
    return {p: point + (start[p] - ref) for p in names}
