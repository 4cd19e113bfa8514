"""Where things are for the heuristic: each surface as a polygon in space, the point of a
surface nearest a goal spot within a patch's reach, and the goal spot of every patch."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from ..model.scene import Scene, Surface
from .goal import Goal

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

    def inner(self) -> shapely.Polygon:
        """The polygon shrunk by EDGE_MARGIN (at most EDGE_SHARE of its inradius)."""
        inradius = float(shapely.maximum_inscribed_circle(self.polygon).length)
        inner = self.polygon.buffer(-min(EDGE_MARGIN, EDGE_SHARE * inradius))
        return self.polygon if inner.is_empty else inner

    def within(self, anchors: list[np.ndarray], reach: float) -> shapely.Geometry:
        """The part of ``inner`` within ``reach`` [m] of an anchor (3,) (the whole of it
        without anchors), a polygon inscribed in the exact set."""
        if not anchors:
            return self.inner()
        discs = []
        for a in anchors:
            x, y, z = self.to_local(a)
            if abs(z) < reach:
                discs.append(shapely.Point(x, y).buffer(float(np.sqrt(reach**2 - z**2)), 32))
        if not discs:
            return shapely.Polygon()
        return self.inner().intersection(shapely.union_all(discs))


def regions(scene: Scene) -> dict[str, Region]:
    """Every surface of the scene as a Region."""
    return {name: Region.of(s) for name, s in scene.surfaces.items()}


def anchor_points(
    key: Iterable[tuple[str, str]], positions: Mapping[str, np.ndarray]
) -> list[np.ndarray]:
    """Where a patch's reach is measured from: the soles in contact of the stance ``key``
    ((patch, surface) pairs), or every contact when none is a sole; positions (3,) [m]."""
    on = [p for p, _ in key]
    return [positions[p] for p in on if "sole" in p] or [positions[p] for p in on]


def pick_target(
    region: Region, spot: np.ndarray, anchors: list[np.ndarray], reach: float
) -> np.ndarray | None:
    """The point (3,) of ``region`` nearest the goal ``spot`` (3,) among those within
    ``reach`` [m] of an anchor (a sole in contact) and EDGE_MARGIN inside; None when no point
    is within reach."""
    area = region.within(anchors, reach)
    if area.is_empty:
        return None
    x, y, _ = region.to_local(spot)
    near, _ = shapely.ops.nearest_points(area, shapely.Point(x, y))
    return region.surface.to_world(np.array([[near.x, near.y]]))[0]


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
