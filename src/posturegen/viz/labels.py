"""Text labels beside points, placed so that no two labels' boxes intersect.

Each label is tried at candidate offsets around its point, nearest first: its preferred
direction (outwards), then directions turned by 30° steps either way, at growing distances.
A candidate is taken when its box (the text's extent, measured once with the figure's
renderer, plus a pad) lies inside the axes and meets neither a label already placed nor a box
to avoid (the points' markers, other text). A label placed farther than ``LEADER_FROM``
points from its point gets a thin leader line. A label that fits nowhere is left out (the
caller is told which)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

DISTANCES = (7.0, 13.0, 20.0, 28.0, 38.0, 50.0)  # [pt] from the point to the label
TURNS = (0, 30, -30, 60, -60, 90, -90, 120, -120, 150, -150, 180)  # [deg] off the preferred way
LEADER_FROM = 14.0  # [pt]: a label this far from its point gets a leader line
PAD = 1.5  # [px] around a label's text


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in display pixels."""

    x0: float
    y0: float
    x1: float
    y1: float

    def meets(self, other: Box) -> bool:
        """Whether the two boxes overlap (touching edges do not)."""
        return (
            self.x0 < other.x1 and other.x0 < self.x1 and self.y0 < other.y1 and other.y0 < self.y1
        )

    def inside(self, other: Box) -> bool:
        """Whether this box lies inside ``other``."""
        return (
            self.x0 >= other.x0
            and self.x1 <= other.x1
            and self.y0 >= other.y0
            and self.y1 <= other.y1
        )

    @classmethod
    def around(cls, xy: np.ndarray, r: float) -> Box:
        """The square of half-side ``r`` around a pixel point."""
        return cls(xy[0] - r, xy[1] - r, xy[0] + r, xy[1] + r)

    @classmethod
    def of(cls, bbox: Any) -> Box:
        """From a matplotlib Bbox."""
        return cls(bbox.x0, bbox.y0, bbox.x1, bbox.y1)


def _alignment(u: np.ndarray) -> tuple[str, str]:
    """Matplotlib's (ha, va) for a label on the side ``u`` (unit, display axes) of its point."""
    ha = "left" if u[0] > 0.3 else ("right" if u[0] < -0.3 else "center")
    va = "bottom" if u[1] > 0.3 else ("top" if u[1] < -0.3 else "center")
    return ha, va


def _box(anchor: np.ndarray, offset: np.ndarray, size: np.ndarray, u: np.ndarray) -> Box:
    """The pixel box of a text of ``size`` (w, h) [px] at ``anchor + offset`` aligned by
    :func:`_alignment` of ``u``."""
    ha, va = _alignment(u)
    x = anchor[0] + offset[0] - {"left": 0.0, "center": 0.5, "right": 1.0}[ha] * size[0]
    y = anchor[1] + offset[1] - {"bottom": 0.0, "center": 0.5, "top": 1.0}[va] * size[1]
    return Box(x - PAD, y - PAD, x + size[0] + PAD, y + size[1] + PAD)


def _rotate(u: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])


def _spot(
    anchor: np.ndarray,
    size: np.ndarray,
    u0: np.ndarray,
    frame: Box,
    taken: Sequence[Box],
    px_per_pt: float,
) -> tuple[float, np.ndarray, Box] | None:
    """The first candidate (distance [pt], direction, box) for a label of ``size`` [px] at
    pixel ``anchor`` that lies in ``frame`` and meets none of ``taken``; None if none does."""
    for dist in DISTANCES:
        for turn in TURNS:
            u = _rotate(u0, turn)
            box = _box(anchor, dist * px_per_pt * u, size, u)
            if box.inside(frame) and not any(box.meets(b) for b in taken):
                return dist, u, box
    return None


def place_labels(
    ax: Any,
    points: np.ndarray,
    texts: Sequence[str],
    directions: np.ndarray,
    avoid: Sequence[Box] = (),
    **style: Any,
) -> list[Any | None]:
    """Annotate ``points`` (k, 2) (data coordinates of ``ax``) with ``texts``, each label on
    the side ``directions[i]`` (k, 2) of its point when it fits there (see the module). The
    labels are placed in the given order; returns each label's Annotation, or None for a label
    that fits nowhere. ``style``: matplotlib text properties (fontsize, color, zorder...)."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    ax.apply_aspect()  # the final data -> display transform
    frame = Box.of(ax.get_window_extent(renderer))
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    anchors = ax.transData.transform(pts)
    taken = list(avoid)
    out: list[Any | None] = []
    for p, anchor, text, d in zip(pts, anchors, texts, np.asarray(directions, float), strict=True):
        probe = ax.text(0, 0, text, **style)
        ext = probe.get_window_extent(renderer)
        probe.remove()
        n = float(np.linalg.norm(d))
        u0 = d / n if n > 1e-12 else np.array([1.0, 1.0]) / np.sqrt(2.0)
        found = _spot(anchor, np.array([ext.width, ext.height]), u0, frame, taken, fig.dpi / 72)
        if found is None:
            out.append(None)
            continue
        dist, u, box = found
        taken.append(box)
        ha, va = _alignment(u)
        leader = {"arrowstyle": "-", "lw": 0.5, "color": style.get("color", "0.3"), "shrinkA": 1}
        out.append(
            ax.annotate(
                text,
                tuple(p),
                xytext=tuple(dist * u),
                textcoords="offset points",
                ha=ha,
                va=va,
                arrowprops=leader if dist >= LEADER_FROM else None,
                **style,
            )
        )
    return out


def text_boxes(artists: Sequence[Any], renderer: Any) -> list[Box]:
    """The drawn extents (display pixels) of text artists (Annotations: their text only)."""
    from matplotlib.text import Text

    return [Box.of(Text.get_window_extent(a, renderer)) for a in artists]
