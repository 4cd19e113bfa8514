"""Planar geometry, by its name before the sub-packages (kept for user code; the modules are
:mod:`posturegen.model.geometry`, :mod:`posturegen.model.ellipse_rows` and
:mod:`posturegen.model.ellipse_fit`). A re-export only: nothing in the package imports it."""

from .model.ellipse_fit import largest_inscribed_ellipse
from .model.ellipse_rows import ellipse_edge_constraints_paper, ellipse_edge_constraints_support
from .model.geometry import ConvexPolygon, Ellipse, intersect

__all__ = [
    "ConvexPolygon",
    "Ellipse",
    "ellipse_edge_constraints_paper",
    "ellipse_edge_constraints_support",
    "intersect",
    "largest_inscribed_ellipse",
]
