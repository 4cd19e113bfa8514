"""A contact sheet: every stance of a sequence file (a climb's, a plan's) as a small 3-D view
in one PNG, left to right and top to bottom, each titled with its stage, so that a path is
seen at a glance (``posturegen plan`` writes it as ``plan.png``)."""

from __future__ import annotations

import math
from pathlib import Path

from ..io.sequence_file import load_sequence
from .scene import force_scale
from .style import PNG_CELL
from .view3d import View3D, draw_3d
from .views import stance_view

TILE = (4.0, 4.5)  # [in] one stance's tile: its 3-D view and its title


def render_contact_sheet(
    sequence: str | Path,
    out_path: str | Path,
    *,
    meshes: str = "visual",
    columns: int = 4,
    dpi: float = 60.0,
) -> Path:
    """Draw every stance of a sequence file into one PNG (``columns`` tiles a row, each
    TILE inches at ``dpi``), forces at one scale for all. Returns the PNG's path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    items = load_sequence(sequence)
    views = [stance_view(p, meshes, PNG_CELL, name) for name, p, _ in items]
    scale = force_scale(views)
    cols = max(1, min(columns, len(views)))
    rows = math.ceil(len(views) / cols)
    fig = Figure(figsize=(TILE[0] * cols, TILE[1] * rows), dpi=dpi)
    FigureCanvasAgg(fig)
    for k, (sv, (name, _, _)) in enumerate(zip(views, items, strict=True)):
        ax = fig.add_subplot(rows, cols, k + 1)
        box = ax.get_position()
        width = round(box.width * fig.bbox.width)
        height = round(box.height * fig.bbox.height)
        draw_3d(ax, View3D.of(sv, scale), width, height)
        ax.set_title(f"{k}. {name}", fontsize=10)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, format="png")
    return out
