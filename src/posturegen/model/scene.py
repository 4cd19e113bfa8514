"""The environment: support surfaces (convex polygons in a local frame) and box obstacles."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _fields as F
from ..errors import InputError
from ..hints import with_hint
from ..plausible import check_size
from .geometry import ConvexPolygon


@dataclass(frozen=True)
class Surface:
    """A convex polygon in the plane z = 0 of ``T_world_surface``; z is the outward normal."""

    name: str
    T_world_surface: pin.SE3
    polygon: ConvexPolygon
    # the solid under the surface [m]: avoided as a box this thick by the links not in
    # contact with the surface (a stair's block, so that its front face is the riser)
    thickness: float = 0.02

    @property
    def normal(self) -> np.ndarray:
        """Outward unit normal in world (3,)."""
        return np.array(self.T_world_surface.rotation[:, 2])

    def to_world(self, points_2d: np.ndarray) -> np.ndarray:
        """(k, 2) points of the surface plane -> (k, 3) world points [m]."""
        pts = np.column_stack([points_2d, np.zeros(len(points_2d))])
        return pts @ self.T_world_surface.rotation.T + self.T_world_surface.translation

    def to_dict(self) -> dict[str, Any]:
        """The ``surface`` entry of a posture file."""
        return {
            "name": self.name,
            "placement": self.T_world_surface.homogeneous.tolist(),
            "vertices": self.polygon.vertices.tolist(),
            "thickness": self.thickness,
        }


@dataclass(frozen=True)
class Obstacle:
    """A box of full extents ``size`` (3,) [m] centred at ``T_world_box``."""

    name: str
    size: np.ndarray
    T_world_box: pin.SE3

    def to_dict(self) -> dict[str, Any]:
        """The ``obstacles`` entry of a posture file."""
        return {
            "name": self.name,
            "box": {"size": self.size.tolist(), "placement": self.T_world_box.homogeneous.tolist()},
        }


@dataclass(frozen=True)
class Scene:
    """Named surfaces and obstacles."""

    surfaces: dict[str, Surface] = field(default_factory=dict)
    obstacles: tuple[Obstacle, ...] = ()

    def surface(self, name: str, field_name: str = "surface") -> Surface:
        """A surface by name, or an InputError listing the known ones."""
        if name not in self.surfaces:
            raise InputError(
                field_name,
                f"no surface named '{name}'",
                with_hint(
                    name,
                    self.surfaces,
                    f"known surfaces: {', '.join(sorted(self.surfaces)) or 'none'}",
                ),
            )
        return self.surfaces[name]

    @staticmethod
    def from_dict(surfaces: Any, obstacles: Any) -> Scene:
        """Parse the ``surfaces`` and ``obstacles`` lists of a problem file."""
        out: dict[str, Surface] = {}
        if not isinstance(surfaces, list):
            raise InputError("surfaces", "expected a list", "write surfaces: [{name: ..., ...}]")
        for i, s in enumerate(surfaces):
            fld = f"surfaces[{i}]"
            s = F.require_mapping(s, fld)
            F.check_keys(s, fld, ["name", "vertices"], ["position", "rpy", "thickness"])
            name = F.string(s["name"], f"{fld}.name")
            if name in out:
                raise InputError(
                    f"{fld}.name", f"duplicate surface name '{name}'", "use unique names"
                )
            T = F.placement(s.get("position", [0, 0, 0]), s.get("rpy", [0, 0, 0]), fld)
            poly = ConvexPolygon(
                F.points2d(s["vertices"], f"{fld}.vertices"), field=f"{fld}.vertices"
            )
            thickness = F.number(s.get("thickness", 0.02), f"{fld}.thickness", positive=True)
            check_size(float(np.ptp(poly.vertices, axis=0).max()), f"{fld}.vertices", "surface")
            out[name] = Surface(name, T, poly, thickness)
        obs: list[Obstacle] = []
        if not isinstance(obstacles, list):
            raise InputError("obstacles", "expected a list", "write obstacles: [{name: ..., ...}]")
        for i, o in enumerate(obstacles):
            fld = f"obstacles[{i}]"
            o = F.require_mapping(o, fld)
            F.check_keys(o, fld, ["name", "box"], ["position", "rpy"])
            size = F.vector(o["box"], 3, f"{fld}.box")
            if np.any(size <= 0):
                raise InputError(
                    f"{fld}.box", "box sizes must be positive", "write [sx, sy, sz] > 0"
                )
            check_size(float(size.max()), f"{fld}.box", "box")
            obs.append(
                Obstacle(
                    F.string(o["name"], f"{fld}.name"),
                    size,
                    F.placement(o.get("position", [0, 0, 0]), o.get("rpy", [0, 0, 0]), fld),
                )
            )
        return Scene(out, tuple(obs))
