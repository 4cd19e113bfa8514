"""A contact's close-up in its surface's plane: both polygons, their intersection, the
ellipse, the force points (normal force labelled in N, tangential part as an arrow)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .labels import Box, place_labels
from .scene import clip_polygon
from .style import ELLIPSE_COLOR, FORCE_COLOR, PATCH_COLOR, SURFACE_COLOR
from .views import ContactView


def _view_rect(c: ContactView) -> tuple[np.ndarray, np.ndarray]:
    """The close-up's window (surface frame): the patch, the ellipse and the force points,
    with a margin."""
    pts = [c.patch2d]
    E = c.ellipse_points()
    if E is not None:
        pts.append(c.to_surface(E))
    if len(c.points3d):
        pts.append(c.to_surface(c.points3d))
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    m = 0.2 * float((hi - lo).max()) + 0.01
    return lo - m, hi + m


def draw_closeup(ax: Any, c: ContactView, scale2d: float) -> None:
    """One contact in its surface's plane: both polygons, their intersection, the ellipse and
    the force points (normal force in N, tangential part as an arrow)."""
    from matplotlib.patches import Polygon as MplPolygon
    from shapely.geometry import Polygon

    lo, hi = _view_rect(c)
    box = ax.get_position()  # widen the window to the cell's shape: more of the surroundings
    shape = box.width * ax.figure.bbox.width / (box.height * ax.figure.bbox.height)
    centre, span = (lo + hi) / 2, hi - lo
    span = np.maximum(span, [span[1] * shape, span[0] / shape])
    lo, hi = centre - span / 2, centre + span / 2
    surf = clip_polygon(c.surface2d, lo - 1.0, hi + 1.0)
    if surf is not None:
        ax.add_patch(MplPolygon(surf, closed=True, fc=SURFACE_COLOR, alpha=0.12, ec="none"))
        ax.add_patch(MplPolygon(surf, closed=True, fill=False, ec=SURFACE_COLOR, lw=2))
    ax.add_patch(MplPolygon(c.patch2d, closed=True, fc=PATCH_COLOR, alpha=0.15, ec="none"))
    ax.add_patch(MplPolygon(c.patch2d, closed=True, fill=False, ec=PATCH_COLOR, lw=2))
    inter = Polygon(c.patch2d).intersection(Polygon(c.surface2d))
    info = []
    if not inter.is_empty and inter.geom_type == "Polygon" and inter.area > 0:
        I = np.asarray(inter.exterior.coords)[:-1]
        ax.add_patch(
            MplPolygon(I, closed=True, fill=False, ec="0.35", lw=0.8, ls="--", hatch="///")
        )
        info.append(f"P1∩P2 {1e4 * inter.area:.0f} cm²")
    E = c.ellipse_points(180)
    if E is not None:
        e2 = c.to_surface(E)
        ax.fill(e2[:, 0], e2[:, 1], color=ELLIPSE_COLOR, alpha=0.18, lw=0)
        ax.plot(*np.vstack([e2, e2[:1]]).T, color=ELLIPSE_COLOR, lw=2)
        centre = c.to_surface(c.ellipse3d[0][None])[0]
        ax.plot(*centre, "+", color=ELLIPSE_COLOR, ms=8)
        r1, r2 = (float(np.linalg.norm(a)) for a in c.ellipse3d[1:])
        info.append(f"ellipse {100 * r1:.1f}×{100 * r2:.1f} cm")
    if c.point3d is not None:
        ax.plot(*c.to_surface(c.point3d[None])[0], "o", color=PATCH_COLOR, ms=6)
    if len(c.points3d):
        info.append(_draw_forces(ax, c, scale2d))
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.25)
    ax.set_title(
        f"{c.name} ({c.type}) on {c.surface}" + ("\n" + ", ".join(info) if info else ""), fontsize=9
    )
    ax.set_xlabel("x in the surface plane [m]", fontsize=7)
    ax.set_ylabel("y [m]", fontsize=7)
    if len(c.points3d):
        _force_labels(ax, c.to_surface(c.points3d), (c.forces3d @ c.T_ws[:3, :3])[:, 2])


def _draw_forces(ax: Any, c: ContactView, scale2d: float) -> str:
    """The force points (sized by their normal force) and their tangential parts (arrows of
    ``scale2d`` [m/N]); returns the normal forces' sum as text."""
    p2 = c.to_surface(c.points3d)
    local = c.forces3d @ c.T_ws[:3, :3]  # surface frame components
    fn = local[:, 2]
    style = {"color": FORCE_COLOR, "zorder": 5}
    ax.scatter(*p2.T, s=marker_area(fn), edgecolors="white", linewidths=0.5, **style)
    if scale2d > 0:
        u, v = local[:, 0] * scale2d, local[:, 1] * scale2d
        kw = {"angles": "xy", "scale_units": "xy", "scale": 1, "width": 0.006}
        ax.quiver(*p2.T, u, v, color=FORCE_COLOR, zorder=6, **kw)
    return f"Σfₙ {fn.sum():.0f} N"


def marker_area(fn: np.ndarray) -> np.ndarray:
    """The force points' marker areas [pt²]: by their normal force ``fn`` (k,) [N]."""
    return 18 + 60 * fn / max(float(fn.max()), 1e-9)


def _force_labels(ax: Any, p2: np.ndarray, fn: np.ndarray) -> list[Any]:
    """The normal forces' labels (N) beside their points (k, 2), outwards from the points'
    centre, the largest first, no two overlapping nor over a point (:mod:`.labels`); forces
    below 5 % of the largest (or 0.5 N) unlabelled. Returns the labels drawn."""
    r_px = np.sqrt(marker_area(fn)) / 2 * ax.figure.dpi / 72  # markers' radii
    ax.apply_aspect()
    markers = [Box.around(xy, r) for xy, r in zip(ax.transData.transform(p2), r_px, strict=True)]
    shown = [i for i in np.argsort(-fn) if fn[i] > max(0.05 * fn.max(), 0.5)]  # [N]
    labels = place_labels(
        ax,
        p2[shown],
        [f"{fn[i]:.0f} N" for i in shown],
        p2[shown] - p2.mean(axis=0),
        avoid=markers,
        fontsize=7.5,
        color="#900000",
        zorder=7,
        gid="force-label",
        bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7},
    )
    return [a for a in labels if a is not None]
