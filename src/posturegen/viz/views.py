"""What is drawn of a posture, in the world frame: the robot's mesh parts placed by forward
kinematics, each contact's polygons, ellipse and forces (also in its surface's plane), the
scene's surfaces and obstacles, the task targets."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import InputError
from .meshes import RobotMeshes, robot_meshes
from .style import PNG_CELL, SLAB


def se3(m: Any, where: str) -> np.ndarray:
    T = np.asarray(m, dtype=float)
    if T.shape != (4, 4):
        raise InputError(where, f"expected a 4x4 matrix, got shape {T.shape}", "a posture file")
    return T


def transform(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return np.asarray(pts, dtype=float) @ T[:3, :3].T + T[:3, 3]


def lift(pts2d: np.ndarray) -> np.ndarray:
    pts2d = np.asarray(pts2d, dtype=float).reshape(-1, 2)
    return np.column_stack([pts2d, np.zeros(len(pts2d))])


@dataclass
class ContactView:
    """One contact, in the world and in its surface's plane (2-D, the surface frame)."""

    name: str
    type: str
    surface: str  # the surface's name
    T_ws: np.ndarray  # surface placement (4, 4)
    surface2d: np.ndarray  # (k, 2) surface polygon, surface frame
    patch2d: np.ndarray  # (k, 2) robot patch, surface frame
    patch3d: np.ndarray  # (k, 3) robot patch, world
    points3d: np.ndarray  # (n, 3) force points, world
    forces3d: np.ndarray  # (n, 3) forces on the robot, world [N]
    ellipse3d: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # centre, two half-axes
    point3d: np.ndarray | None = None  # the point of a point contact, world

    def to_surface(self, pts: np.ndarray) -> np.ndarray:
        """World points (k, 3) -> surface-plane points (k, 2)."""
        R, p = self.T_ws[:3, :3], self.T_ws[:3, 3]
        return ((np.asarray(pts, dtype=float).reshape(-1, 3) - p) @ R)[:, :2]

    def ellipse_points(self, n: int = 72) -> np.ndarray | None:
        """(n, 3) world points of the ellipse's boundary, or None."""
        if self.ellipse3d is None:
            return None
        c, a1, a2 = self.ellipse3d
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return c + np.outer(np.cos(t), a1) + np.outer(np.sin(t), a2)


@dataclass
class StanceView:
    """Everything drawn for one posture, in the world frame."""

    name: str
    posture: dict[str, Any]
    meshes: RobotMeshes
    part_poses: list[np.ndarray]  # (4, 4) per mesh part
    contacts: list[ContactView]
    surfaces: list[tuple[str, np.ndarray, np.ndarray, float]]  # name, T_ws, (k, 2), thickness
    obstacles: list[tuple[str, np.ndarray, np.ndarray]]  # name, full size (3,), T_wb
    targets: list[tuple[str, np.ndarray]]
    weight: float  # [N]

    def world_triangles(self) -> np.ndarray:
        """(m, 3, 3) robot triangles in the world."""
        out = [
            transform(T, part.vertices)[part.triangles]
            for part, T in zip(self.meshes.parts, self.part_poses, strict=True)
        ]
        return np.concatenate(out) if out else np.zeros((0, 3, 3))


def stance_view(
    posture: dict[str, Any], kind: str = "visual", cell: float = PNG_CELL, name: str = ""
) -> StanceView:
    """Forward kinematics of a posture and the world geometry of its scene and contacts."""
    meshes = robot_meshes(posture, kind, cell)
    model = meshes.model
    q = np.asarray(posture["q"], dtype=float)
    if q.shape != (model.nq,):
        raise InputError(
            "q", f"{q.size} numbers for a robot with nq = {model.nq}", "a posture of this URDF"
        )
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    poses = [data.oMi[p.joint_id].homogeneous @ p.placement for p in meshes.parts]

    contacts, surfaces = [], {}
    for i, c in enumerate(posture.get("contacts", [])):
        where = f"contacts[{i}]"
        try:
            contacts.append(_contact_view(c, model, data, where))
            s, cv = c["surface"], contacts[-1]
            thick = float(s.get("thickness", SLAB))
            surfaces.setdefault(s["name"], (s["name"], cv.T_ws, cv.surface2d, thick))
        except InputError:
            raise
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise InputError(where, f"malformed contact ({exc})", "give a posture file") from exc
    for s in posture.get("surfaces") or []:  # the whole scene, when the file has it
        T = se3(s["placement"], f"surfaces[{s.get('name')}].placement")
        verts = np.asarray(s["vertices"], dtype=float)
        surfaces.setdefault(s["name"], (s["name"], T, verts, float(s.get("thickness", SLAB))))
    obstacles = [
        (
            str(o.get("name", "")),
            np.asarray(o["box"]["size"], dtype=float),
            se3(o["box"]["placement"], "obstacles.box.placement"),
        )
        for o in posture.get("obstacles") or []
    ]
    targets = [
        (str(t.get("frame", "")), np.asarray(t["target"], dtype=float))
        for t in posture.get("tasks") or []
        if t.get("target") is not None
    ]
    g = np.linalg.norm(posture.get("gravity") or [0, 0, -9.81])
    weight = float(pin.computeTotalMass(model) * g)
    return StanceView(
        name=name,
        posture=posture,
        meshes=meshes,
        part_poses=poses,
        contacts=contacts,
        surfaces=list(surfaces.values()),
        obstacles=obstacles,
        targets=targets,
        weight=weight,
    )


def _contact_view(c: dict[str, Any], model: pin.Model, data: pin.Data, where: str) -> ContactView:
    T_ws = se3(c["surface"]["placement"], f"{where}.surface.placement")
    rp = c["robot_patch"]
    if not model.existFrame(rp["frame"]):
        raise InputError(
            f"{where}.robot_patch.frame", f"no frame '{rp['frame']}'", "a posture of this URDF"
        )
    T_wf = data.oMf[model.getFrameId(rp["frame"])].homogeneous
    T_wp = T_wf @ se3(rp["placement"], f"{where}.robot_patch.placement")
    patch3d = transform(T_wp, lift(rp["vertices"]))
    forces = c.get("forces") or []
    pts = np.array([f["point"] for f in forces], dtype=float).reshape(-1, 3)
    fs = np.array([f["force"] for f in forces], dtype=float).reshape(-1, 3)
    ell = c.get("ellipse")
    ellipse3d = None
    if ell:
        ellipse3d = (
            np.asarray(ell["center"], dtype=float),
            np.asarray(ell["axes"][0], dtype=float),
            np.asarray(ell["axes"][1], dtype=float),
        )
    point = c.get("point")
    view = ContactView(
        name=str(c.get("name", "")),
        type=str(c.get("type", "")),
        surface=str(c["surface"].get("name", "")),
        T_ws=T_ws,
        surface2d=np.asarray(c["surface"]["vertices"], dtype=float),
        patch2d=np.zeros((0, 2)),
        patch3d=patch3d,
        points3d=pts,
        forces3d=fs,
        ellipse3d=ellipse3d,
        point3d=None if not point else np.asarray(point["world"], dtype=float),
    )
    view.patch2d = view.to_surface(patch3d)
    return view
