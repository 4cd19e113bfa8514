"""Pictures of posture files: a paper-style figure (PNG) and a self-contained 3D viewer (HTML).

- :func:`render_png` (:mod:`.figure`) draws a posture as in the paper's figures 1, 6 and 7: the
  robot with its meshes, the scene's surfaces and obstacles, each contact's polygons (robot
  patch green, surface red), its ellipse (blue) and its forces (red arrows); beside it a
  close-up of each contact in its surface's plane (:mod:`.closeup`). The 3-D view
  (:mod:`.view3d`) is an orthographic z-buffer of the meshes (:func:`rasterize`, NumPy), its
  camera chosen so that the scene hides little of the robot and its contacts; the contacts are
  drawn over it.
- :func:`write_html` (:mod:`.html`) writes ONE HTML file with an interactive three.js view.

The modules, each importing only those before it: ``style`` (colours, constants) · ``meshes``
(the robot's decimated meshes) · ``views`` (what is drawn, in the world) · ``raster`` (camera,
window, z-buffer) · ``scene`` (the scene's triangles) · ``labels`` (text that does not overlap)
· ``obstacles`` (boxes at their depth) · ``triad`` (world axes, scale bar) · ``view3d`` ·
``closeup`` · ``figure`` · ``html``.
"""

from ..io.posture_file import load_posture_any
from ..io.sequence_file import (
    SEQUENCE_SCHEMA,
    is_sequence,
    load_sequence,
    read_json,
    write_sequence,
)
from .contact_sheet import render_contact_sheet
from .figure import Drawing, draw_figure, render_png
from .html import viewer_html, write_html
from .meshes import MeshPart, RobotMeshes, decimate, mesh_cache_dir, robot_meshes, shape_mesh
from .raster import Camera, Frame, rasterize
from .style import HTML_CELL, MESH_KINDS, PNG_CELL, VIEW_AZIMUTHS, VIEW_ELEVATION
from .views import ContactView, StanceView, stance_view

__all__ = [
    "HTML_CELL",
    "MESH_KINDS",
    "PNG_CELL",
    "SEQUENCE_SCHEMA",
    "VIEW_AZIMUTHS",
    "VIEW_ELEVATION",
    "Camera",
    "ContactView",
    "Drawing",
    "Frame",
    "MeshPart",
    "RobotMeshes",
    "StanceView",
    "decimate",
    "draw_figure",
    "is_sequence",
    "load_posture_any",
    "load_sequence",
    "mesh_cache_dir",
    "rasterize",
    "render_contact_sheet",
    "read_json",
    "render_png",
    "robot_meshes",
    "shape_mesh",
    "stance_view",
    "viewer_html",
    "write_html",
    "write_sequence",
]
