"""The interactive viewer: ONE HTML file with a three.js view (orbit, zoom, pan; toggles for
polygons, ellipses, forces and the scene; a slider through the stances of a sequence). three.js
is inlined from the vendored npm package in ``data/js`` (see ``tools/vendor_js.sh``): the file
works offline and fetches nothing."""

from __future__ import annotations

import base64
import html
import importlib.resources
import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..io.posture_file import load_posture_any
from ..io.sequence_file import is_sequence, load_sequence, read_json
from .scene import bounds, force_scale, scene_mesh
from .style import (
    ELLIPSE_COLOR,
    FORCE_COLOR,
    HTML_CELL,
    OBSTACLE_RGB,
    PATCH_COLOR,
    ROBOT_RGB,
    SURFACE_COLOR,
)
from .view3d import View3D
from .views import ContactView, StanceView, lift, stance_view, transform


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _rounded(a: np.ndarray, digits: int = 5) -> list[Any]:
    return np.round(np.asarray(a, dtype=float), digits).tolist()


def _scene_blob(sv: StanceView) -> dict[str, Any]:
    """The stance's surfaces (:func:`scene_mesh`, unclipped) and obstacles as world triangle
    soups: base64 float32 positions, uint8 RGB per vertex for the surfaces."""
    surfaces, rgb, boxes = scene_mesh(sv)
    out: dict[str, Any] = {}
    if len(surfaces):
        rgb8 = np.repeat(np.round(255 * rgb), 3, axis=0).astype(np.uint8)
        out["surfaces"] = {"v": _b64(surfaces.astype("<f4")), "c": _b64(rgb8)}
    if len(boxes):
        out["obstacles"] = {"v": _b64(boxes.astype("<f4"))}
    return out


def _contact_json(c: ContactView) -> dict[str, Any]:
    E = c.ellipse_points(64)
    return {
        "name": c.name,
        "type": c.type,
        "normal": _rounded(c.T_ws[:3, 2]),
        "surface": _rounded(transform(c.T_ws, lift(c.surface2d))),
        "patch": _rounded(c.patch3d),
        "ellipse": None if E is None else _rounded(E),
        "point": None if c.point3d is None else _rounded(c.point3d),
        "forces": _rounded(np.hstack([c.points3d, c.forces3d]), 4),
    }


def _js_asset(name: str) -> str:
    return (importlib.resources.files("posturegen") / "data" / "js" / name).read_text("utf-8")


def _script_json(value: Any) -> str:
    """JSON for an HTML ``<script type="application/json">`` block: ``<`` escaped, so neither
    ``</script>`` nor ``<!--`` can appear in it."""
    return json.dumps(value, separators=(",", ":")).replace("<", "\\u003c")


def _mesh_json(part: Any) -> dict[str, Any]:
    """A mesh part as the viewer reads it: base64 little-endian vertices and triangles."""
    wide = len(part.vertices) > 65535
    return {
        "name": part.name,
        "v": _b64(part.vertices.astype("<f4")),
        "i": _b64(part.triangles.astype("<u4" if wide else "<u2")),
        "wide": wide,
    }


def viewer_html(views: Sequence[StanceView], files: Sequence[str], title: str) -> str:
    """The viewer's HTML text for stances of one robot (their meshes are the first one's)."""
    mesh_json = [_mesh_json(p) for p in views[0].meshes.parts]
    scenes: list[dict[str, Any]] = []
    stages = []
    scale = force_scale(views)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for sv, file in zip(views, files, strict=True):
        blob = _scene_blob(sv)
        if blob not in scenes:
            scenes.append(blob)
        b_lo, b_hi = bounds(sv, sv.world_triangles(), scale)
        lo, hi = np.minimum(lo, b_lo), np.maximum(hi, b_hi)
        poses = np.array([T[:3, :] for T in sv.part_poses]).astype("<f4")
        stages.append(
            {
                "name": sv.name,
                "file": file,
                "success": bool(sv.posture.get("success")),
                "message": str(sv.posture.get("message", "")),
                "poses": _b64(poses),
                "scene": scenes.index(blob),
                "contacts": [_contact_json(c) for c in sv.contacts],
                "targets": [_rounded(t) for _, t in sv.targets],
            }
        )
    centre = (lo + hi) / 2
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    cam = View3D.of(views[0], scale).cam  # from where the first stance's figure looks
    eye = centre - 0.9 * radius / math.sin(math.radians(15)) * cam.forward
    data = {
        "title": title,
        "colors": {
            "robot": _hex(ROBOT_RGB),
            "patch": PATCH_COLOR,
            "surface": SURFACE_COLOR,
            "ellipse": ELLIPSE_COLOR,
            "force": FORCE_COLOR,
            "obstacle": _hex(OBSTACLE_RGB),
        },
        "view": {"target": _rounded(centre), "eye": _rounded(eye), "radius": 0.9 * radius},
        "forceScale": scale,
        "forceLabel": f"10 cm = {0.1 / scale:.0f} N" if scale > 0 else "no force",
        "meshes": mesh_json,
        "scenes": scenes,
        "stages": stages,
    }
    version = _js_asset("VERSION").split()[0]
    fields = {
        "TITLE": html.escape(title),
        "THREE_VERSION": html.escape(version),
        "THREE_LICENSE": html.escape(_js_asset("LICENSE")).replace("--", "- -"),
        "THREE_JS": _script_json(_js_asset("three.module.min.js")),
        "ORBIT_JS": _script_json(_js_asset("OrbitControls.js")),
        "DATA": _script_json(data),
    }
    template = (importlib.resources.files("posturegen") / "data" / "viewer.html").read_text("utf-8")
    return re.sub(r"@@([A-Z_]+)@@", lambda m: fields[m.group(1)], template)


def _hex(rgb: Sequence[float]) -> str:
    return "#" + "".join(f"{round(255 * x):02x}" for x in rgb)


def write_html(
    source: str | Path | dict[str, Any],
    out_path: str | Path,
    *,
    meshes: str = "visual",
    cell: float = HTML_CELL,
) -> Path:
    """Write the interactive viewer of a posture (file or dict) or of a sequence file (see the
    module docstring) to one self-contained HTML file."""
    if isinstance(source, dict):
        items = [("posture", load_posture_any(source), "posture")]
        title = f"{source['robot'].get('name', 'robot')} posture"
    else:
        path = Path(source)
        data = read_json(path)
        if is_sequence(data):
            items = [(n, p, f.name) for n, p, f in load_sequence(path)]
            robot, n = items[0][1]["robot"].get("name", "robot"), len(items)
            title = f"{robot} — {path.name} ({n} stance{'s' if n > 1 else ''})"
        else:
            items = [(path.stem, load_posture_any(path), path.name)]
            title = f"{items[0][1]['robot'].get('name', 'robot')} — {path.name}"
    views = [stance_view(p, meshes, cell, name) for name, p, _ in items]
    text = viewer_html(views, [f for _, _, f in items], title)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    return out
