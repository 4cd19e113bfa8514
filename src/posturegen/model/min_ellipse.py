"""The default minimum contact ellipse of a floating contact: a real fraction of the robot patch.

A floating contact's ellipse is the region its forces act on (support) or that a later fixed
contact stands on (geometric). By default both its semi-axes are at least
``MIN_RADIUS_FRACTION`` × r_in, r_in = min(inradius of the robot patch, inradius of the
surface polygon), the inradius being the radius of the largest disc inside a polygon. So the
contact region holds a disc ¾ as wide as the patch's own: a hand put on a table lies mostly on
it, a foot put on a step stands on ¾ of its width, and no contact is a corner on a corner
(the former default, 5 mm, let TALOS' hands rest on a table's corners). The surface's inradius
keeps the default feasible on surfaces thinner than the patch (a 2.5 cm rung: 9.4 mm): placed
on the surface's incircle, the patch's incircle holds both discs. ¾ rather than 1 leaves the
non-inclusive contacts of the paper room to overhang an edge, and the conservative rows
(the support form's ε, the smoothed eigenvalues of a scaled plane) room to be met.
"""

from __future__ import annotations

import itertools

import numpy as np

from .geometry import ConvexPolygon

# The default minimum semi-axes as a fraction of the smaller of the two polygons' inradii.
# TALOS: the sole (18.5 × 11.4 cm, r_in 5.7 cm) 4.3 cm, the hand (r_in 2.96 cm) 2.2 cm. On
# the table of tests/test_cop.py the hands lie 73 % on it (41 % with ½, 89 % with 0.9).
MIN_RADIUS_FRACTION = 0.75


def inscribed_disc(polygon: ConvexPolygon) -> tuple[np.ndarray, float]:
    """(centre (2,), radius) of the largest disc in a convex polygon: max r such that
    n_k·c + r <= b_k for every edge k. The optimum touches three edges (or two parallel
    ones, then also a third at some optimum), so it is the best feasible solution of the
    3×3 systems of the edge triples (exact; n <= 20 edges in practice)."""
    normals, offsets = polygon.halfplanes()
    best_c, best_r = polygon.centroid, float(polygon.distance_inside(polygon.centroid[None])[0])
    tol = 1e-12 * max(1.0, float(np.abs(offsets).max()))
    for tri in itertools.combinations(range(len(offsets)), 3):
        A = np.column_stack([normals[list(tri)], np.ones(3)])
        if abs(np.linalg.det(A)) < 1e-12:
            continue
        cx, cy, r = np.linalg.solve(A, offsets[list(tri)])
        if r > best_r and np.all(normals @ np.array([cx, cy]) + r <= offsets + tol):
            best_c, best_r = np.array([cx, cy]), float(r)
    return best_c, best_r


def default_min_radii(patch: ConvexPolygon, surface: ConvexPolygon) -> tuple[float, float]:
    """Both semi-axes' default minimum [m]: MIN_RADIUS_FRACTION × the smaller inradius."""
    r = MIN_RADIUS_FRACTION * min(inscribed_disc(patch)[1], inscribed_disc(surface)[1])
    return (r, r)
