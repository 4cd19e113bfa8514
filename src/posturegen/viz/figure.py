"""The paper-style figure (PNG): the 3-D view on the left, a close-up of each contact on the
right, the legend and the title. Matplotlib's Agg canvas only: no display needed."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io.posture_file import load_posture_any
from .closeup import draw_closeup
from .scene import force_scale
from .style import (
    ELLIPSE_COLOR,
    FORCE_COLOR,
    OBSTACLE_EDGE_COLOR,
    OBSTACLE_RGB,
    PATCH_COLOR,
    PNG_CELL,
    SURFACE_COLOR,
    VIEW_ELEVATION,
)
from .triad import Triad
from .view3d import View3D, draw_3d
from .views import StanceView, stance_view


def _title(posture: dict[str, Any], file: str | None) -> str:
    """Robot, what the posture is (its climb stage, else its file) and whether it was
    verified."""
    robot = posture["robot"].get("name", "robot")
    stage = posture.get("stage")
    if isinstance(stage, dict) and "name" in stage:
        what = f"{stage.get('sequence', 'sequence')}, stage {int(stage.get('index', 0)) + 1}: "
        what += str(stage["name"])
    else:
        what = file or "posture"
    why = str(posture.get("message", "?"))
    state = "verified" if posture.get("success") else f"NOT verified: {why[:80]}"
    return f"{robot} — {what} — {state}"


@dataclass(frozen=True)
class Drawing:
    """A drawn figure: matplotlib's Figure (Agg canvas), its 3-D view and what the view's
    world axes and scale bar are."""

    figure: Any
    view: View3D
    triad: Triad


def draw_figure(
    posture: str | Path | dict[str, Any],
    *,
    meshes: str = "visual",
    dpi: float = 100.0,
    title: str | None = None,
    azimuth: float | None = None,
    elevation: float = VIEW_ELEVATION,
) -> Drawing:
    """The figure of a posture (file path or dict), not saved (see :func:`render_png`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    data = load_posture_any(posture)
    sv = stance_view(data, meshes, PNG_CELL)
    scale = force_scale([sv])
    view = View3D.of(sv, scale, azimuth, elevation)
    fig = Figure(figsize=(16, 9), dpi=dpi)
    FigureCanvasAgg(fig)
    n = len(sv.contacts)
    ncols = 0 if n == 0 else (1 if n <= 2 else 2)
    nrows = max(1, math.ceil(n / max(ncols, 1)))
    # the 3-D view as wide as its content at the figure's height, within 40-62 % of the width
    share = float(np.clip(view.aspect * 0.83 * 9 / 16, 0.4, 0.62))
    gs = fig.add_gridspec(
        nrows,
        1 + ncols,
        width_ratios=[share / (1 - share) * max(ncols, 1) * 1.15] + [1.0] * ncols,
        left=0.01,
        right=0.98,
        top=0.9,
        bottom=0.07,
        wspace=0.28,
        hspace=0.45,
    )
    ax3 = fig.add_subplot(gs[:, 0])
    box = ax3.get_position()
    width, height = (round(box.width * fig.bbox.width), round(box.height * fig.bbox.height))
    triad = draw_3d(ax3, view, width, height)
    for k, c in enumerate(sv.contacts):
        ax = fig.add_subplot(gs[k // ncols, 1 + k % ncols])
        draw_closeup(ax, c, 0.5 * scale)
    if title is None:
        title = _title(data, Path(posture).name if isinstance(posture, str | Path) else None)
    fig.suptitle(title, fontsize=13)
    _legend(fig, sv, scale)
    return Drawing(fig, view, triad)


def _legend(fig: Any, sv: StanceView, scale: float) -> None:
    """The colours' legend under the figure, and the meshes' note in its corner."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    force = f"contact force ({0.1 / scale:.0f} N per 10 cm)" if scale > 0 else "contact force"
    handles = [
        Patch(fc=PATCH_COLOR, alpha=0.5, ec=PATCH_COLOR, label="robot patch (P1)"),
        Patch(fc=SURFACE_COLOR, alpha=0.3, ec=SURFACE_COLOR, label="surface (P2)"),
        Patch(fc=ELLIPSE_COLOR, alpha=0.4, ec=ELLIPSE_COLOR, label="contact ellipse"),
        Line2D([], [], color=FORCE_COLOR, lw=2, label=force),
    ]
    if sv.obstacles:
        handles.append(
            Patch(fc=OBSTACLE_RGB, alpha=0.6, ec=OBSTACLE_EDGE_COLOR, label="obstacle (box)")
        )
    if sv.targets:
        handles.append(Line2D([], [], color="black", marker="x", ls="none", label="task target"))
    fig.legend(handles=handles, loc="lower left", ncol=len(handles), fontsize=9, frameon=False)
    fig.text(
        0.99,
        0.01,
        f"{sv.meshes.kind} meshes, {sv.meshes.triangle_count} triangles "
        f"(decimated on a {1000 * PNG_CELL:.0f} mm grid)",
        ha="right",
        va="bottom",
        fontsize=7,
        color="0.4",
    )


def render_png(
    posture: str | Path | dict[str, Any],
    out_path: str | Path,
    *,
    meshes: str = "visual",
    dpi: float = 100.0,
    title: str | None = None,
    azimuth: float | None = None,
    elevation: float = VIEW_ELEVATION,
) -> Path:
    """Draw a posture (file path or dict) to a PNG: the 3-D view on the left, with the world
    axes and a scale bar in a corner, a close-up of each contact in its own plane on the right.
    1600 x 900 pixels at ``dpi`` 100.

    The camera looks from ``azimuth`` degrees off the robot's heading (default: the first of
    :data:`VIEW_AZIMUTHS` that hides little of the robot behind the scene), ``elevation``
    degrees above the horizon."""
    drawing = draw_figure(
        posture, meshes=meshes, dpi=dpi, title=title, azimuth=azimuth, elevation=elevation
    )
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    drawing.figure.savefig(out, dpi=dpi, format="png")
    return out
