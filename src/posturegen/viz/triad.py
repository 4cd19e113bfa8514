"""The 3-D view's world axes and scale bar, where they hide least of the view.

The view is orthographic, so a world direction has the same screen direction everywhere: the
triad draws the world axes x, y, z as arrows from one point, each the screen projection of a
unit vector (an axis along the line of sight is a short arrow; nearly along it, a dot). The
scale bar is a horizontal segment of a round length (1, 2, 5 × 10ⁿ m, and 25 cm), the longest
that fits in its space: a length in the image plane. Both go on a translucent white card on
the side of the view where it covers least of what the view draws (the robot, the scene, the
contacts and their forces): the top side and the corners first when they tie."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .labels import Box
from .raster import Camera, Frame

LENGTHS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0)  # scale bar [m]
CARD = (170, 70)  # the card's size [px at 100 dpi]
ARROW = 26  # an axis arrow's length for a unit vector in the image plane [px at 100 dpi]
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
INK = "0.12"


@dataclass(frozen=True)
class Triad:
    """What was drawn: the side of the view, the triad's origin and the arrows' tips (data
    coordinates of the view: screen metres), the scale bar's ends and its length [m], and the
    card's box in display pixels."""

    side: str
    origin: np.ndarray
    tips: dict[str, np.ndarray]
    bar: tuple[np.ndarray, np.ndarray]
    length: float
    card: Box


def scale_text(length: float) -> str:
    """A scale bar's label: ``20 cm``, ``1 m``."""
    return f"{100 * length:g} cm" if length < 1 else f"{length:g} m"


def _place(busy: np.ndarray, w: int, h: int) -> tuple[str, int, int]:
    """Where (side, left, top pixel) a w x h card covers the fewest busy pixels of the mask
    ``busy`` (H, W): positions along the four sides, every 10 % of a side, the top side first
    and the corners first among ties (within 0.5 % of the card)."""
    H, W = busy.shape
    count = np.pad(busy.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    t = np.linspace(0.0, 1.0, 11)
    t = t[np.argsort(np.minimum(t, 1 - t), kind="stable")]  # corners first
    candidates = [("top", x, 0) for x in t * (W - w)]
    candidates += [("bottom", x, H - h) for x in t * (W - w)]
    candidates += [(side, x, y) for y in t * (H - h) for side, x in (("left", 0), ("right", W - w))]
    best, where = None, ("top", 0, 0)
    for side, x, y in candidates:
        x, y = int(np.clip(round(x), 0, max(W - w, 0))), int(np.clip(round(y), 0, max(H - h, 0)))
        x1, y1 = min(x + w, W), min(y + h, H)
        n = count[y1, x1] - count[y, x1] - count[y1, x] + count[y, x]
        if best is None or n < best - 0.005 * w * h:
            best, where = n, (side, x, y)
    return where


def draw_triad(ax: Any, cam: Camera, frame: Frame, busy: np.ndarray) -> Triad:
    """Draw the world axes and the scale bar on the 3-D view's axes ``ax`` (data: screen
    metres of ``frame``), on the side of the view where they cover the fewest pixels of
    ``busy`` (frame.height, frame.width): what the view draws there."""
    from matplotlib.patches import FancyBboxPatch

    k = ax.figure.dpi / 100.0
    w, h = round(CARD[0] * k), round(CARD[1] * k)
    inset = round(6 * k)
    side, left, top = _place(busy, w + 2 * inset, h + 2 * inset)
    left, top = left + inset, top + inset
    res = frame.res

    def data(px: float, py: float) -> np.ndarray:  # view pixel -> data (screen metres)
        return np.array([frame.x0 + px * res, frame.y1 - py * res])

    lo, hi = data(left, top + h), data(left + w, top)
    ax.add_patch(
        FancyBboxPatch(
            lo,
            *(hi - lo),
            boxstyle=f"round,pad=0,rounding_size={4 * k * res}",
            fc="white",
            ec="0.8",
            lw=0.6,
            alpha=0.85,
            zorder=10,
            gid="triad-card",
        )
    )
    reach = (1.35 * ARROW + 8) * k  # [px] of the triad around its origin, letters included
    origin = data(left + 8 * k + reach, top + 0.6 * h)
    unit = ARROW * k * res
    tips = {name: origin + unit * cam.screen(np.array(v)) for name, v in AXES.items()}
    for name in AXES:
        _axis(ax, origin, name, tips, unit)
    start = left + 16 * k + 2 * reach  # the scale bar beside the triad
    bar, length = _scale_bar(
        ax, data(start, top + 0.7 * h), (left + w - 10 * k - start) * res, k * res
    )
    card = Box.of(ax.transData.transform_bbox(_bbox(lo, hi)))
    return Triad(side, origin, tips, bar, length, card)


def busy_mask(img: np.ndarray, frame: Frame, xy: np.ndarray, reach: int = 6) -> np.ndarray:
    """The pixels (frame.height, frame.width) a view draws: the image ``img`` where it is not
    white, and ``reach`` pixels around the screen points ``xy`` (k, 2) drawn over it."""
    busy = img.min(axis=-1) < 0.97
    px = np.floor(frame.pixels(xy)).astype(np.int64).reshape(-1, 2)
    for dx in range(-reach, reach + 1):
        for dy in range(-reach, reach + 1):
            x, y = px[:, 0] + dx, px[:, 1] + dy
            ok = (x >= 0) & (x < frame.width) & (y >= 0) & (y < frame.height)
            busy[y[ok], x[ok]] = True
    return busy


def _bbox(lo: np.ndarray, hi: np.ndarray) -> Any:
    from matplotlib.transforms import Bbox

    return Bbox([lo, hi])


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-300), 0.0, 1.0))
    return float(np.linalg.norm(p - a - t * ab))


def _letter_at(
    origin: np.ndarray, name: str, tips: dict[str, np.ndarray], unit: float
) -> np.ndarray:
    """Where an axis' letter goes: beyond its tip when that is 0.3 ``unit`` from the other
    arrows, else the one of eight spots around the tip farthest from them."""
    d = tips[name] - origin
    n = float(np.linalg.norm(d))
    turns = np.radians(np.arange(0, 360, 45))
    spots = [tips[name] + 0.35 * unit * np.array([np.cos(t), np.sin(t)]) for t in turns]
    if n > 0.2 * unit:
        spots.insert(0, tips[name] + 0.35 * unit * d / n)
    others = [tips[o] for o in tips if o != name and np.linalg.norm(tips[o] - origin) > 0]

    def room(p: np.ndarray) -> float:
        return min((_distance_to_segment(p, origin, t) for t in others), default=np.inf)

    if n > 0.2 * unit and room(spots[0]) >= 0.3 * unit:
        return spots[0]
    return max(spots, key=room)


def _axis(ax: Any, origin: np.ndarray, name: str, tips: dict[str, np.ndarray], unit: float) -> None:
    """One world axis from ``origin`` to its tip (``unit``: the data length of a unit vector
    in the image plane), an arrow, or a dot when it is nearly along the line of sight; its
    letter where it meets no other arrow (:func:`_letter_at`)."""
    tip = tips[name]
    if np.linalg.norm(tip - origin) > 0.2 * unit:
        ax.annotate(
            "",
            xy=tuple(tip),
            xytext=tuple(origin),
            textcoords="data",
            zorder=11,
            arrowprops={
                "arrowstyle": "-|>",
                "color": INK,
                "lw": 1.3,
                "mutation_scale": 9,
                "shrinkA": 0,
                "shrinkB": 0,
            },
        ).set_gid(f"world-axis-{name}")
    else:  # along the line of sight: a dot
        ax.plot(*tip, "o", color=INK, ms=3, zorder=11, gid=f"world-axis-{name}")
    at = _letter_at(origin, name, tips, unit)
    ax.text(
        *at,
        name,
        ha="center",
        va="center",
        fontsize=9,
        fontweight="bold",
        color=INK,
        zorder=11,
        gid=f"world-axis-label-{name}",
    )


def _scale_bar(
    ax: Any, start: np.ndarray, room: float, px: float
) -> tuple[tuple[np.ndarray, np.ndarray], float]:
    """A horizontal scale bar from ``start`` (data), the longest round length within ``room``
    (data length); ``px`` is a pixel's data length. Returns its ends and its length [m]."""
    length = max([v for v in LENGTHS if v <= room] or [LENGTHS[0]])
    a, b = start, start + np.array([length, 0.0])
    ax.plot(
        [a[0], b[0]],
        [a[1], b[1]],
        color=INK,
        lw=2.5,
        solid_capstyle="butt",
        zorder=11,
        gid="scale-bar",
    )
    for end in (a, b):
        ax.plot([end[0], end[0]], [end[1] - 4 * px, end[1] + 4 * px], color=INK, lw=1.2, zorder=11)
    ax.text(
        (a[0] + b[0]) / 2,
        a[1] + 8 * px,
        scale_text(length),
        ha="center",
        va="bottom",
        fontsize=8.5,
        color=INK,
        zorder=11,
        gid="scale-label",
    )
    return (a, b), length
