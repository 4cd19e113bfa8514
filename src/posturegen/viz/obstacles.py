"""Obstacles (boxes) in the figure's z-buffer, at their depth.

A box is drawn only where it is the nearest surface: there its shaded faces are laid over what
is behind it, translucent (an arm reaching behind a box stays visible through it, tinted),
and its edges are drawn where two of its faces meet or where its outline meets what is behind.
Where the robot (or a surface) is nearer than the box, the pixels are the robot's own: neither
the box's faces nor its edges are drawn over it."""

from __future__ import annotations

import numpy as np

from .raster import Camera, Frame, rasterize, shade
from .style import OBSTACLE_EDGE_COLOR, OBSTACLE_RGB

OPACITY = 0.65  # of a box's faces over what is behind them
TRIANGLES_PER_BOX = 12  # of meshes.box_mesh: face k is triangles k and k + 6


def _hex_rgb(color: str) -> np.ndarray:
    return np.array([int(color[i : i + 2], 16) / 255 for i in (1, 3, 5)])


def nearest_boxes(
    cam: Camera, frame: Frame, boxes: np.ndarray, zbuf: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where a box is nearer than the depth image ``zbuf`` of ``frame``: a mask (h, w), and the
    box triangle seen at each pixel (-1 where none)."""
    bz, bids = rasterize(
        frame.pixels(cam.screen(boxes)), cam.depth(boxes), frame.width, frame.height
    )
    return (bids >= 0) & (bz < zbuf), bids


def _edges(front: np.ndarray, bids: np.ndarray) -> np.ndarray:
    """Edge pixels of the nearest boxes: two neighbours on different faces, or a box beside
    no box; widened by a pixel on each side, inside the boxes' nearest part."""
    face = np.where(bids >= 0, (bids // TRIANGLES_PER_BOX) * 6 + bids % 6, -1)
    edge = np.zeros(front.shape, dtype=bool)
    for axis in (0, 1):
        f, k, e = (np.moveaxis(a, axis, 0) for a in (face, front, edge))
        crease = (f[1:] != f[:-1]) & (f[1:] >= 0) & (f[:-1] >= 0)  # faces of boxes
        outline = (f[1:] >= 0) != (f[:-1] >= 0)  # a box beside no box
        e[1:] |= k[1:] & (crease & k[:-1] | outline)
        e[:-1] |= k[:-1] & (crease & k[1:] | outline)
    wide = edge.copy()
    wide[1:] |= edge[:-1]
    wide[:-1] |= edge[1:]
    wide[:, 1:] |= edge[:, :-1]
    wide[:, :-1] |= edge[:, 1:]
    return wide & front


def draw_obstacles(
    img: np.ndarray, cam: Camera, frame: Frame, boxes: np.ndarray, zbuf: np.ndarray
) -> None:
    """Lay the boxes (m, 3, 3) world triangles over ``img`` (h, w, 3), the RGB image of
    ``frame`` whose depth image is ``zbuf``, where they are nearest (in place)."""
    if len(boxes) == 0:
        return
    front, bids = nearest_boxes(cam, frame, boxes, zbuf)
    colours = shade(boxes, np.tile(OBSTACLE_RGB, (len(boxes), 1)), cam)
    img[front] = (1 - OPACITY) * img[front] + OPACITY * colours[bids[front]]
    img[_edges(front, bids)] = _hex_rgb(OBSTACLE_EDGE_COLOR)
