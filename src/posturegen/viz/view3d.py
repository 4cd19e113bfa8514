"""The figure's 3-D view: the camera that hides little of the robot, the z-buffered shaded
image of the robot, the scene and the obstacles, and the contacts drawn over it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .labels import place_labels
from .obstacles import draw_obstacles
from .raster import Camera, Frame, base_yaw, rasterize, shade
from .scene import content_points, scene_mesh, surface_edges
from .style import (
    ELLIPSE_COLOR,
    FORCE_COLOR,
    PATCH_COLOR,
    ROBOT_RGB,
    SURFACE_COLOR,
    VIEW_AZIMUTHS,
    VIEW_ELEVATION,
)
from .triad import Triad, busy_mask, draw_triad
from .views import ContactView, StanceView, lift, transform

SUPERSAMPLE = 2  # pixels per figure pixel on each side (antialiasing)
OUTLINE_DEPTH = 0.025  # [m]: a depth step drawn as an outline


def _around_contacts(sv: StanceView, reach: float = 0.1, n: int = 7) -> np.ndarray:
    """World points (k, 3) on each contact's surface around its robot patch (``reach`` [m]
    beyond it), lifted 2 mm off the surface: what a view of the contact should not hide."""
    from shapely.geometry import Point, Polygon

    out = []
    for c in sv.contacts:
        lo, hi = c.patch2d.min(axis=0) - reach, c.patch2d.max(axis=0) + reach
        surface = Polygon(c.surface2d)
        grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)))
        pts = [p for p in grid.reshape(2, -1).T if surface.covers(Point(p))]
        if pts:
            out.append(transform(c.T_ws, lift(np.array(pts)) + [0, 0, 0.002]))
    return np.vstack(out) if out else np.zeros((0, 3))


def choose_camera(
    sv: StanceView, robot: np.ndarray, scene: np.ndarray, content: np.ndarray, elevation: float
) -> Camera:
    """The first of :data:`VIEW_AZIMUTHS` whose score is (nearly) the best one's. The score,
    from low-resolution z-buffers: the part of the robot the scene leaves visible, plus the
    part of the contacts' surfaces around the contacts that the rest of the scene leaves
    visible, plus half the part of the contacts whose surface faces the camera."""
    heading = base_yaw(sv.posture)
    normals = np.array([c.T_ws[:3, 2] for c in sv.contacts]).reshape(-1, 3)
    around = _around_contacts(sv)
    robot = robot[:: max(1, len(robot) // 15000)]  # a sample is enough for a fraction
    tris = np.concatenate([robot, scene])
    nr, size = len(robot), 128
    top = 1.0 + (1.0 if len(around) else 0.0) + (0.5 if len(normals) else 0.0)  # best possible
    scores = []
    for azim in VIEW_AZIMUTHS:
        cam = Camera.orbit(heading + azim, elevation)
        frame = Frame.fit(cam.screen(content), size, size)
        P, Z = frame.pixels(cam.screen(tris)), cam.depth(tris)
        alone = (rasterize(P[:nr], Z[:nr], size, size)[1] >= 0).sum()
        ids = rasterize(P, Z, size, size)[1]
        robot_seen = ((ids >= 0) & (ids < nr)).sum() / max(alone, 1)
        score = float(robot_seen)
        if len(around):
            zbuf = rasterize(P[nr:], Z[nr:], size, size)[0]
            score += float(np.mean(_visible(cam, frame, zbuf, around)))
        if len(normals):
            score += 0.5 * float(np.mean(normals @ -cam.forward > 0.05))
        scores.append(score)
        if score >= top - 0.05:  # no later candidate can beat it by more
            break
    best = max(scores)
    azim = next(a for a, s in zip(VIEW_AZIMUTHS, scores, strict=False) if s >= best - 0.05)
    return Camera.orbit(heading + azim, elevation)


def _image(
    cam: Camera,
    frame: Frame,
    robot: np.ndarray,
    scene: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, Frame]:
    """The shaded view of the robot and the scene (:func:`scene_mesh`) as RGB floats
    (frame.height, frame.width, 3), the depth image of the supersampled frame, and that
    frame."""
    big = frame.scaled(SUPERSAMPLE)
    surfaces, surface_rgb, boxes = scene
    tris = np.concatenate([robot, surfaces])
    base = np.vstack([np.tile(ROBOT_RGB, (len(robot), 1)), surface_rgb])
    flat = np.r_[np.zeros(len(robot)), np.full(len(surfaces), 0.6)]
    colours = np.vstack([shade(tris, base, cam, flat), np.ones((1, 3))])  # last: background
    zbuf, ids = rasterize(big.pixels(cam.screen(tris)), cam.depth(tris), big.width, big.height)
    img = colours[ids]  # -1: the background
    # outlines: depth steps, and the robot's edge against the scene, on the nearer side
    kind = np.where(ids < 0, 0, np.where(ids < len(robot), 1, 2))
    edge = np.zeros(ids.shape, dtype=bool)
    for axis in (0, 1):
        z, k, e = (np.moveaxis(a, axis, 0) for a in (zbuf, kind, edge))
        with np.errstate(invalid="ignore"):
            step = (np.abs(z[1:] - z[:-1]) > OUTLINE_DEPTH) | (k[1:] != k[:-1])
        near = z[1:] < z[:-1]
        e[1:] |= step & near
        e[:-1] |= step & ~near
    img[edge & (ids >= 0)] *= 0.45
    draw_obstacles(img, cam, big, boxes, zbuf)  # at their depth
    k = SUPERSAMPLE
    return img.reshape(frame.height, k, frame.width, k, 3).mean(axis=(1, 3)), zbuf, big


def _visible(cam: Camera, frame: Frame, zbuf: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Whether world points (k, 3) are in front of the z-buffer of ``frame`` (or outside it),
    within 1 cm and 3 pixels."""
    px = np.floor(frame.pixels(cam.screen(pts))).astype(np.int64)
    inside = (px[:, 0] >= 0) & (px[:, 0] < frame.width) & (px[:, 1] >= 0)
    inside &= px[:, 1] < frame.height
    z = np.full(len(pts), np.inf)
    z[inside] = zbuf[px[inside, 1], px[inside, 0]]
    return cam.depth(pts) <= z + 0.01 + 3 * frame.res


def _draw_edges(
    ax: Any, cam: Camera, big: Frame, zbuf: np.ndarray, seg: np.ndarray, color: str
) -> None:
    """An edge (2, 3): solid where seen, dotted where hidden."""
    n = max(2, int(np.linalg.norm(np.diff(cam.screen(seg), axis=0)) / big.res / 2))
    pts = seg[0] + np.linspace(0, 1, n)[:, None] * (seg[1] - seg[0])
    xy = cam.screen(pts)
    seen = _visible(cam, big, zbuf, pts)
    for flag in (True, False):
        y = xy.copy()
        y[seen != flag] = np.nan  # runs of one kind
        if np.isfinite(y).any():
            style = {"lw": 1.6, "ls": "-"} if flag else {"lw": 0.9, "ls": (0, (2, 2))}
            ax.plot(y[:, 0], y[:, 1], color=color, zorder=4, **style)


@dataclass(frozen=True)
class View3D:
    """What the figure's 3-D view draws: the robot's world triangles, the points it must show,
    the scene (:func:`scene_mesh`, big surfaces clipped to ``box``) and the camera."""

    sv: StanceView
    scale: float  # force arrows [m/N]
    robot: np.ndarray
    content: np.ndarray
    box: tuple[np.ndarray, np.ndarray]
    scene: tuple[np.ndarray, np.ndarray, np.ndarray]
    cam: Camera

    @classmethod
    def of(
        cls,
        sv: StanceView,
        scale: float,
        azimuth: float | None = None,
        elevation: float = VIEW_ELEVATION,
    ) -> View3D:
        """The view of a stance (see :func:`render_png` for the camera)."""
        robot = sv.world_triangles()
        content = content_points(sv, robot, scale)
        lo, hi = content.min(axis=0), content.max(axis=0)
        margin = 0.35 + 0.1 * float((hi - lo).max())
        box = (lo - margin, hi + margin)  # where big surfaces (ground, walls) are drawn
        scene = scene_mesh(sv, box)
        if azimuth is None:
            cam = choose_camera(sv, robot, scene[0], content, elevation)
        else:
            cam = Camera.orbit(base_yaw(sv.posture) + azimuth, elevation)
        return cls(sv, scale, robot, content, box, scene, cam)

    @property
    def aspect(self) -> float:
        """Width / height of the content on the screen."""
        span = np.ptp(self.cam.screen(self.content), axis=0)
        return float(span[0] / max(span[1], 1e-9))


def draw_3d(ax: Any, view: View3D, width: int, height: int) -> Triad:
    """The robot, the scene and the contacts, orthographic, on a 2-D axes of ``width`` x
    ``height`` pixels: a z-buffered image of the meshes, the contacts drawn on top, the world
    axes and a scale bar in a corner (returned), the contacts' names where no two overlap."""
    sv, cam = view.sv, view.cam
    frame = Frame.fit(cam.screen(view.content), width, height, margin=0.03)
    img, zbuf, big = _image(cam, frame, view.robot, view.scene)
    ax.imshow(img, extent=frame.extent, interpolation="none", zorder=1)
    drawn = set()
    for c in sv.contacts:  # the contacts' surfaces' edges, hidden parts dotted
        if c.surface not in drawn:
            drawn.add(c.surface)
            for seg in surface_edges(c.T_ws, c.surface2d, *view.box):
                _draw_edges(ax, cam, big, zbuf, seg, SURFACE_COLOR)
    for c in sv.contacts:  # on top of everything
        _draw_contact(ax, cam, c, view.scale)
    for _, t in sv.targets:
        ax.plot(*cam.screen(t), "x", color="black", ms=8, mew=2, zorder=9)
    ax.set_xlim(frame.extent[0], frame.extent[1])
    ax.set_ylim(frame.extent[2], frame.extent[3])
    ax.set_aspect("equal")
    ax.set_axis_off()
    triad = draw_triad(ax, cam, frame, busy_mask(img, frame, cam.screen(_overlays(view))))
    place_labels(
        ax,
        np.array([cam.screen(c.patch3d.mean(axis=0)) for c in sv.contacts]).reshape(-1, 2),
        [c.name for c in sv.contacts],
        np.tile([1.0, -1.0], (len(sv.contacts), 1)),  # below right of the patch
        avoid=[triad.card],
        fontsize=8,
        color="#1b5e20",
        zorder=9,
        gid="contact-label",
        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7},
    )
    return triad


def _overlays(view: View3D) -> np.ndarray:
    """World points (k, 3) of what is drawn over the image: the contacts' patches, ellipses
    and force arrows (sampled along them), the targets."""
    pts = [np.zeros((0, 3))]
    for c in view.sv.contacts:
        pts.append(c.patch3d)
        if (E := c.ellipse_points(24)) is not None:
            pts.append(E)
        for t in np.linspace(0.0, 1.0, 12):
            pts.append(c.points3d + t * view.scale * c.forces3d)
    pts += [t[None] for _, t in view.sv.targets]
    return np.vstack(pts)


def _draw_contact(ax: Any, cam: Camera, c: ContactView, scale: float) -> None:
    """A contact's patch (green), ellipse (blue), point, and force arrows (red, ``scale``
    [m/N]), drawn over the image."""
    from matplotlib.patches import FancyArrowPatch, Polygon

    patch = cam.screen(c.patch3d)
    ax.add_patch(Polygon(patch, closed=True, fc=PATCH_COLOR, alpha=0.35, ec="none", zorder=5))
    ax.add_patch(Polygon(patch, closed=True, fill=False, ec=PATCH_COLOR, lw=1.6, zorder=5))
    E = c.ellipse_points()
    if E is not None:
        style = {"fc": ELLIPSE_COLOR, "alpha": 0.4, "ec": ELLIPSE_COLOR, "lw": 1.6, "zorder": 6}
        ax.add_patch(Polygon(cam.screen(E), closed=True, **style))
    if c.point3d is not None:
        ax.plot(*cam.screen(c.point3d), "o", color=PATCH_COLOR, ms=5, zorder=7)
    if len(c.forces3d) and scale > 0:
        a = cam.screen(c.points3d)
        b = cam.screen(c.points3d + scale * c.forces3d)
        for p, q in zip(a, b, strict=True):
            ax.add_patch(
                FancyArrowPatch(
                    p,
                    q,
                    arrowstyle="-|>",
                    mutation_scale=9,
                    color=FORCE_COLOR,
                    lw=1.4,
                    shrinkA=0,
                    shrinkB=0,
                    zorder=8,
                )
            )
        ax.plot(*a.T, "o", color=FORCE_COLOR, ms=2.5, zorder=8)
