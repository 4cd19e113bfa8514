"""An orthographic camera, a screen window in pixels, and a NumPy z-buffer of triangles."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


def _view_direction(azim: float, elev: float) -> np.ndarray:
    """The unit vector from the scene towards a camera at azimuth and elevation [deg]."""
    a, e = np.radians(azim), np.radians(elev)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def base_yaw(posture: dict[str, Any]) -> float:
    x, y, z, w = np.asarray(posture["q"][3:7], dtype=float)
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


@dataclass(frozen=True)
class Camera:
    """An orthographic camera: the screen's axes ``right`` and ``up`` and the viewing
    direction ``forward`` (from the camera into the scene), unit world vectors."""

    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray

    @classmethod
    def orbit(cls, azim: float, elev: float) -> Camera:
        """The camera at azimuth ``azim`` (world, deg) and elevation ``elev`` (deg, |elev| <
        90), z up on the screen."""
        forward = -_view_direction(azim, float(np.clip(elev, -89.0, 89.0)))
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        return cls(right, np.cross(right, forward), forward)

    def screen(self, pts: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> screen coordinates (..., 2) [m]."""
        pts = np.asarray(pts, dtype=float)
        return np.stack([pts @ self.right, pts @ self.up], axis=-1)

    def depth(self, pts: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> depth (...) [m], larger is farther."""
        return np.asarray(pts, dtype=float) @ self.forward


@dataclass(frozen=True)
class Frame:
    """A screen window: ``width`` x ``height`` pixels of ``res`` metres, its top-left corner
    at screen (``x0``, ``y1``)."""

    x0: float
    y1: float
    res: float
    width: int
    height: int

    @classmethod
    def fit(cls, xy: np.ndarray, width: int, height: int, margin: float = 0.04) -> Frame:
        """The window of ``width`` x ``height`` pixels that shows the screen points ``xy``
        (k, 2) centred, with ``margin`` (a fraction of the window) on every side."""
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        span = np.maximum(hi - lo, 1e-3)
        res = float(max(span[0] / width, span[1] / height)) / (1 - 2 * margin)
        c = (lo + hi) / 2
        return cls(c[0] - res * width / 2, c[1] + res * height / 2, res, width, height)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) in screen metres (matplotlib's ``imshow`` extent)."""
        return (
            self.x0,
            self.x0 + self.res * self.width,
            self.y1 - self.res * self.height,
            self.y1,
        )

    def scaled(self, k: int) -> Frame:
        """The same window with ``k`` times as many pixels on each side."""
        return Frame(self.x0, self.y1, self.res / k, self.width * k, self.height * k)

    def pixels(self, xy: np.ndarray) -> np.ndarray:
        """Screen points (..., 2) [m] -> pixel coordinates (..., 2) (x right, y down)."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([(xy[..., 0] - self.x0) / self.res, (self.y1 - xy[..., 1]) / self.res], -1)


def _expand(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For ``counts`` (m,): the owner of each of the ``sum(counts)`` items and its rank."""
    owner = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    return owner, np.arange(len(owner)) - starts[owner]


def rasterize(
    P: np.ndarray, Z: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray]:
    """Z-buffer of triangles: ``P`` (n, 3, 2) pixel coordinates (x right, y down; pixel (i, j)
    is the unit square at (i, j), sampled at its centre), ``Z`` (n, 3) depths (smaller is
    nearer). Returns the depth image (height, width) (inf where empty) and the index of the
    triangle seen at each pixel (-1 where none). Vectorized over row spans: the work is
    proportional to the rows and pixels the triangles cover."""
    P = np.asarray(P, dtype=float).reshape(-1, 3, 2)
    Z = np.asarray(Z, dtype=float).reshape(-1, 3)
    zbuf = np.full(width * height, np.inf, dtype=np.float32)
    ids = np.full(width * height, -1, dtype=np.int32)
    a, b, c = P[:, 0], P[:, 1], P[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    y0 = np.maximum(np.ceil(P[:, :, 1].min(axis=1) - 0.5), 0)
    y1 = np.minimum(np.floor(P[:, :, 1].max(axis=1) - 0.5), height - 1)
    x_lo, x_hi = P[:, :, 0].min(axis=1), P[:, :, 0].max(axis=1)
    keep = np.flatnonzero((np.abs(area) > 1e-9) & (y1 >= y0) & (x_hi >= 0) & (x_lo <= width))
    if len(keep) == 0:
        return zbuf.reshape(height, width), ids.reshape(height, width)
    a, b, c, area, Zk = a[keep], b[keep], c[keep], area[keep], Z[keep]
    # inward half-planes of the edges, A x + B y + C >= 0, (k, 3)
    s = np.sign(area)[:, None]
    p, q = np.stack([a, b, c], 1), np.stack([b, c, a], 1)
    dx, dy = q[..., 0] - p[..., 0], q[..., 1] - p[..., 1]
    A, B, C = -s * dy, s * dx, s * (dy * p[..., 0] - dx * p[..., 1])
    # the depth plane z = al x + be y + ga
    dzb, dzc = Zk[:, 1] - Zk[:, 0], Zk[:, 2] - Zk[:, 0]
    al = (dzb * (c[:, 1] - a[:, 1]) - dzc * (b[:, 1] - a[:, 1])) / area
    be = (dzc * (b[:, 0] - a[:, 0]) - dzb * (c[:, 0] - a[:, 0])) / area
    ga = Zk[:, 0] - al * a[:, 0] - be * a[:, 1]
    # one span per (triangle, row): the pixel centres x with every A x >= -(B y + C)
    tri, k = _expand((y1[keep] - y0[keep] + 1).astype(np.int64))
    row = y0[keep].astype(np.int64)[tri] + k
    yc = row + 0.5
    rhs = -(B[tri] * yc[:, None] + C[tri])
    At = A[tri]
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = rhs / At
    x_l = np.where(At > 0, bound, -np.inf).max(axis=1)
    x_r = np.where(At < 0, bound, np.inf).min(axis=1)
    empty = ((At == 0) & (rhs > 0)).any(axis=1)
    c0 = np.maximum(np.ceil(x_l - 0.5), 0)
    c1 = np.minimum(np.floor(x_r - 0.5), width - 1)
    count = np.where(empty, 0, np.maximum(c1 - c0 + 1, 0)).astype(np.int64)
    span, j = _expand(count)
    x = c0[span].astype(np.int64) + j
    t = tri[span]
    z = (al[t] * (x + 0.5) + be[t] * yc[span] + ga[t]).astype(np.float32)
    pix = row[span] * width + x
    np.minimum.at(zbuf, pix, z)
    seen = z <= zbuf[pix]
    ids[pix[seen]] = keep[t[seen]]
    return zbuf.reshape(height, width), ids.reshape(height, width)


def shade(
    tris: np.ndarray, base: np.ndarray, cam: Camera, flat: float | np.ndarray = 0.0
) -> np.ndarray:
    """Flat-shaded colours (k, 3) of world triangles: a key light above-left of the camera,
    a head light, ambient; two-sided. ``flat`` in [0, 1] fades the lights towards the base
    colour (the scene's planes: light, so that the robot stands out)."""
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
    n *= np.where(n @ cam.forward > 0, -1.0, 1.0)[:, None]  # towards the camera
    key = -cam.forward + 0.9 * cam.up - 0.6 * cam.right
    key /= np.linalg.norm(key)
    light = 0.30 + 0.55 * np.clip(n @ key, 0, 1) + 0.22 * np.clip(-(n @ cam.forward), 0, 1)
    return np.clip(base * ((1 - np.asarray(flat)) * light + flat)[:, None], 0, 1)
