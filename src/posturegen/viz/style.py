"""What the figures look like: colours, mesh decimation cells, the camera's candidate
directions (constants shared by the figure and the viewer)."""

from __future__ import annotations

MESH_KINDS = ("visual", "collision")
VIEW_AZIMUTHS = (-35.0, -60.0, -15.0, -90.0, 35.0, 60.0, 15.0, 90.0)  # the camera's candidate
# azimuths from the robot's heading [deg], preferred first (-35: front, robot's right side)
VIEW_ELEVATION = 18.0  # [deg]
PNG_CELL = 0.006  # decimation cell of the figure's meshes [m] (the z-buffer makes it cheap)
HTML_CELL = 0.006  # decimation cell of the viewer's meshes [m]
SLAB = 0.02  # thickness of a surface's solid when the posture file does not give it [m]

ROBOT_RGB = (0.70, 0.72, 0.75)
PATCH_COLOR = "#1a9a3a"  # robot patch: green
SURFACE_COLOR = "#d62728"  # surface polygon: red
ELLIPSE_COLOR = "#1f3fd0"  # contact ellipse: blue
FORCE_COLOR = "#e00000"  # contact forces: red arrows
SCENE_RGB = (0.87, 0.84, 0.77)  # support surfaces
CONTACT_SURFACE_RGB = (0.97, 0.84, 0.81)  # support surfaces in contact (tinted red)
OBSTACLE_RGB = (0.62, 0.70, 0.80)
OBSTACLE_EDGE_COLOR = "#3b5b85"
