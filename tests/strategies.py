"""Hypothesis strategies that draw real inputs (so that a failure shrinks to a small one):
convex polygons from drawn points, postures from drawn joint values within their limits."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import shapely
from hypothesis import assume
from hypothesis import strategies as st

from posturegen.errors import InputError
from posturegen.model.geometry import ConvexPolygon

COORD = st.floats(-2.0, 2.0, allow_nan=False, allow_infinity=False)


@st.composite
def convex_polygons(draw: st.DrawFn, min_points: int = 3, max_points: int = 12) -> ConvexPolygon:
    """The convex hull of 3..12 drawn points in [-2, 2]², counter-clockwise or clockwise, of
    area > 1e-2 and edges > 1e-4 (a degenerate hull is rejected by ``assume``)."""
    pts = np.array(
        draw(st.lists(st.tuples(COORD, COORD), min_size=min_points, max_size=max_points))
    )
    hull = shapely.MultiPoint(pts).convex_hull
    assume(hull.geom_type == "Polygon")
    ring = np.asarray(hull.exterior.coords)[:-1]
    if draw(st.booleans()):
        ring = ring[::-1]  # clockwise input must work too
    try:
        P = ConvexPolygon(ring)
    except InputError:
        assume(False)
        raise
    assume(P.area > 1e-2)
    assume(np.min(np.linalg.norm(np.diff(P.vertices, axis=0), axis=1)) > 1e-4)
    return P


@st.composite
def postures(draw: st.DrawFn, model: pin.Model) -> np.ndarray:
    """q (nq,) of a free-flyer ``model``: a base position in [-2, 2]³, a unit quaternion from
    4 drawn numbers, each joint within its limits (clipped to [-3, 3] where unbounded)."""
    lo = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -3.0)[7:]
    hi = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, 3.0)[7:]
    lo, hi = np.maximum(lo, -3.0), np.minimum(hi, 3.0)
    unit = st.floats(0.0, 1.0, allow_nan=False)
    fractions = np.array(draw(st.lists(unit, min_size=lo.size, max_size=lo.size)))
    base = np.array(draw(st.lists(COORD, min_size=3, max_size=3)))
    quat = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4)))
    assume(np.linalg.norm(quat) > 0.1)
    return np.concatenate([base, quat / np.linalg.norm(quat), lo + fractions * (hi - lo)])
