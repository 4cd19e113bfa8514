"""Options of a contact ellipse (paper sec. IV) and the thin-patch scaling of sec. IV-F."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.geometry import ConvexPolygon


def thin_scaling(polygon: ConvexPolygon, mode: str | float = "auto") -> np.ndarray:
    """S (2, 2), the geometric scaling of sec. IV-F: S = U·diag(1, k)·Uᵀ with U the principal
    axes of ``polygon`` (the minor one second). ``auto``: for a patch thinner than 5 cm,
    k = min(0.1 m / minor width, 10), so a 2.5 cm rung is seen 10 cm wide by the solver, else
    k = 1 (a mild scaling only costs the exact radius bounds); ``none``: k = 1; a number: k."""
    v = polygon.vertices - polygon.centroid
    _, vecs = np.linalg.eigh(v.T @ v)
    U = vecs[:, ::-1]  # major axis first
    widths = np.ptp(v @ U, axis=0)
    if mode == "none":
        k = 1.0
    elif mode == "auto":
        k = min(0.1 / max(widths[1], 1e-9), 10.0) if widths[1] < 0.05 else 1.0
    else:
        k = float(mode)
    return U @ np.diag([1.0, k]) @ U.T


@dataclass(frozen=True)
class EllipseOptions:
    """The contact ellipse of a non-inclusive contact (sec. IV).

    ``formulation``: ``paper`` (eqs. 4-6, scaled by the edge length) or ``support`` (the
    support-function form n·c + sqrt(rx²(n·u)² + ry²(n·v)²) <= b). ``min_radii`` (m) bound the
    real ellipse's semi-axes from below (the smaller bound on the minor axis, the larger on the
    major one; None: :func:`posturegen.model.min_ellipse.default_min_radii`); ``min_area`` (m²) its
    area; ``maximize_area`` weights eq. 8's cost -π·rx·ry/min(A(P1), A(P2)); ``scaling`` is
    the thin-patch scaling of sec. IV-F."""

    formulation: str = "support"
    min_radii: tuple[float, float] | None = None
    min_area: float = 0.0
    maximize_area: float = 0.0
    scaling: str | float = "auto"
