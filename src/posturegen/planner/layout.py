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
# [m] a solid (another surface's slab, an obstacle box) over a surface whose underside is less
# than this above it leaves no room for a patch there: its footprint is cut from the surface's
# candidate points, and what it hides from an anchor too (the ground under a flight of stairs:
# ATLAS' touches of the ground under step 2, 0.12 m high, were declared infeasible by IPOPT
# after 905-1558 iterations, 8.6 s of a 22.9 s plan). Below the 0.225 m between the rungs of
# the vertical ladder: a foot goes on a rung under the next one
HEADROOM = 0.2
SHADOW_M = 10.0  # [m] how far a cut's shadow reaches from its anchor
FLUSH = 1e-3  # [m] a solid whose top is this close to the plane stands beside it, not on it


@dataclass(frozen=True)
class Region:
    """A surface's polygon in its plane, for distances and candidate points."""

    surface: Surface
    polygon: shapely.Geometry  # (surface frame, 2-D): the surface less its cuts
    cuts: tuple[shapely.Geometry, ...] = ()  # footprints of the solids over it (2-D, convex)

    @classmethod
    def of(cls, surface: Surface, solids: Iterable[np.ndarray] = ()) -> Region:
        """The surface's polygon less the footprint of each solid ((k, 3) world corners [m])
        that lies over it lower than HEADROOM."""
        region = cls(surface, shapely.Polygon(surface.polygon.vertices))
        cuts = [region.footprint(c) for c in solids]
        cuts = [c for c in cuts if c is not None]
        if not cuts:
            return region
        return cls(surface, region.polygon.difference(shapely.union_all(cuts)), tuple(cuts))

    def footprint(self, corners_world: np.ndarray) -> shapely.Geometry | None:
        """The convex hull in the plane of a solid's corners (k, 3) [m] when the solid
        occupies the space from the plane to HEADROOM above it, else None."""
        T = self.surface.T_world_surface
        local = (corners_world - T.translation) @ T.rotation  # (k, 3)
        if local[:, 2].max() <= FLUSH or local[:, 2].min() >= HEADROOM:
            return None
        return shapely.MultiPoint(local[:, :2]).convex_hull

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
        """The part of ``inner`` within ``reach`` [m] of an anchor (3,) and not hidden from it
        by a cut (the whole of it without anchors), a polygon inscribed in the exact set."""
        if not anchors:
            return self.inner()
        seen = []
        for a in anchors:
            x, y, z = self.to_local(a)
            if abs(z) < reach:
                disc = shapely.Point(x, y).buffer(float(np.sqrt(reach**2 - z**2)), 32)
                seen.append(self._unhidden(disc, np.array([x, y])))
        if not seen:
            return shapely.Polygon()
        return self.inner().intersection(shapely.union_all(seen))

    def _unhidden(self, area: shapely.Geometry, anchor: np.ndarray) -> shapely.Geometry:
        """``area`` less each cut's shadow seen from ``anchor`` (2,) (a cut under the anchor
        hides nothing: the anchor stands on it)."""
        shadows = []
        for cut in self.cuts:
            if cut.contains(shapely.Point(*anchor)):
                continue
            v = np.asarray(cut.exterior.coords)[:-1]  # (k, 2)
            away = v - anchor
            far = anchor + SHADOW_M * away / np.linalg.norm(away, axis=1, keepdims=True)
            shadows.append(shapely.MultiPoint(np.vstack([v, far])).convex_hull)
        return area.difference(shapely.union_all(shadows)) if shadows else area


def solid_corners(scene: Scene) -> dict[str, np.ndarray]:
    """Each solid of the scene by name, as its corners (k, 3) in world [m]: a surface's slab
    (its polygon and the same ``thickness`` below) and each obstacle box."""
    out = {}
    for name, s in scene.surfaces.items():
        top = s.polygon.vertices
        bottom = s.to_world(top) - s.thickness * s.normal
        out[name] = np.vstack([s.to_world(top), bottom])
    unit = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) / 2
    for box in scene.obstacles:
        T = box.T_world_box
        out[f"obstacle {box.name}"] = (unit * box.size) @ T.rotation.T + T.translation
    return out


def regions(scene: Scene) -> dict[str, Region]:
    """Every surface of the scene as a Region, less what stands over it (HEADROOM)."""
    solids = solid_corners(scene)
    return {
        name: Region.of(s, [c for other, c in solids.items() if other != name])
        for name, s in scene.surfaces.items()
    }


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
