"""Pictures of posture files: a paper-style figure (PNG) and a self-contained 3D viewer (HTML).

- :func:`render_png` draws a posture as in the paper's figures 1, 6 and 7: the robot with its
  meshes, the scene's surfaces and obstacles, each contact's polygons (robot patch green,
  surface red), its ellipse (blue) and its forces (red arrows); beside it a close-up of each
  contact in its surface's plane (both polygons, their intersection, the ellipse, the force
  points). The 3-D view is an orthographic z-buffer of the meshes (:func:`rasterize`, NumPy),
  its camera chosen so that the scene hides little of the robot and its contacts; the contacts
  are drawn over it. Matplotlib with the Agg canvas only: no display needed.
- :func:`write_html` writes ONE HTML file with an interactive three.js view (orbit, zoom, pan;
  toggles for polygons, ellipses, forces and the scene; a slider through the stances of a
  sequence). three.js is inlined from the vendored npm package in ``data/js`` (see
  ``tools/vendor_js.sh``): the file works offline and fetches nothing.

Meshes come from the posture's URDF through Pinocchio's GeometryModel (visual or collision
meshes), decimated by vertex clustering on a grid of ``cell`` metres.

A *sequence file* (JSON, ``"schema": "posturegen.sequence/1"``) lists the stances of a climb::

    {"schema": "posturegen.sequence/1",
     "stages": [{"name": "1: left foot on rung 2", "posture": "stage-01.json"},
                {"name": "2: right hand released", "posture": "stage-02.json"}]}

``stages[i].posture`` is a posture file path, relative to the sequence file's folder (or
absolute); ``stages[i].name`` is the stance's label; other keys are kept and ignored. Every
stage must use the same robot. :func:`write_sequence` writes one.
"""

from __future__ import annotations

import base64
import functools
import html
import importlib.resources
import json
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .errors import InputError
from .verify import SCHEMA, SEQUENCE_SCHEMA, load_posture
from .verify import read_json as read_json_file

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


# --------------------------------------------------------------------------- input
def load_posture_any(posture: str | Path | dict[str, Any]) -> dict[str, Any]:
    """A posture dict from a posture file path or a dict (both checked like ``verify``)."""
    if isinstance(posture, dict):
        if posture.get("schema") != SCHEMA:
            raise InputError("posture: schema", f'expected "{SCHEMA}"', "give a posture dict")
        for key in ("robot", "q", "contacts"):
            if key not in posture:
                raise InputError(f"posture: {key}", "missing", "give a posture written by solve")
        return posture
    return load_posture(posture)


def read_json(path: str | Path) -> dict[str, Any]:
    """A JSON object from a file, or an InputError naming the file."""
    data = read_json_file(path, "give a posture or sequence file", "give a JSON file")
    if not isinstance(data, dict):
        raise InputError(str(path), "not a JSON object", "give a posture or sequence file")
    return data


def is_sequence(data: dict[str, Any]) -> bool:
    """Whether a JSON object is a sequence file (its schema, or a ``stages`` list)."""
    return data.get("schema") == SEQUENCE_SCHEMA or isinstance(data.get("stages"), list)


def load_sequence(path: str | Path) -> list[tuple[str, dict[str, Any], Path]]:
    """The stances of a sequence file: ``(name, posture dict, posture path)`` each."""
    path = Path(path)
    data = read_json(path)
    stages = data.get("stages")
    if not isinstance(stages, list) or not stages:
        raise InputError(f"{path}: stages", "missing or empty", "list the stances' posture files")
    out = []
    for i, stage in enumerate(stages):
        where = f"{path}: stages[{i}]"
        if not isinstance(stage, dict) or not isinstance(stage.get("posture"), str):
            raise InputError(where, "needs a 'posture' file name", 'write {"posture": "a.json"}')
        file = Path(stage["posture"])
        if not file.is_absolute():
            file = path.parent / file
        name = str(stage.get("name", file.stem))
        out.append((name, load_posture_any(file), file))
    urdfs = {str(p["robot"].get("urdf")) for _, p, _ in out}
    if len(urdfs) > 1:
        raise InputError(f"{path}: stages", "the stances use different robots", "one robot")
    return out


def write_sequence(path: str | Path, stages: Sequence[dict[str, Any]], **extra: Any) -> Path:
    """Write a sequence file: ``stages`` are dicts with ``posture`` (a path) and ``name``;
    posture paths are stored relative to the sequence file's folder when they are inside it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, stage in enumerate(stages):
        if "posture" not in stage:
            raise InputError(f"stages[{i}].posture", "missing", "give the posture file path")
        file = Path(stage["posture"])
        try:
            rel = str(file.resolve().relative_to(path.parent.resolve()))
        except ValueError:
            rel = str(file.resolve())
        rows.append({**stage, "name": str(stage.get("name", file.stem)), "posture": rel})
    path.write_text(json.dumps({"schema": SEQUENCE_SCHEMA, **extra, "stages": rows}, indent=1))
    return path


# --------------------------------------------------------------------------- meshes
def decimate(
    vertices: np.ndarray, triangles: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: vertices in one ``cell`` [m] grid cube merge to their mean;
    degenerate and duplicate triangles are dropped. ``cell <= 0`` keeps the mesh."""
    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if cell <= 0 or len(T) == 0:
        return V, T
    keys = np.floor(V / cell).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    uniq, inv = np.unique(flat, return_inverse=True)
    inv = inv.ravel()
    W = np.zeros((len(uniq), 3))
    np.add.at(W, inv, V)
    W /= np.bincount(inv, minlength=len(uniq))[:, None]
    T2 = inv[T]
    T2 = T2[(T2[:, 0] != T2[:, 1]) & (T2[:, 1] != T2[:, 2]) & (T2[:, 0] != T2[:, 2])]
    if len(T2) == 0:
        return W[:0], T2
    _, first = np.unique(np.sort(T2, axis=1), axis=0, return_index=True)
    T2 = T2[np.sort(first)]
    used, T3 = np.unique(T2, return_inverse=True)
    return W[used], T3.reshape(-1, 3)


_BOX_EDGES = [(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit]  # of _box_mesh


def _box_mesh(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    s = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    T = [(a, b, c) for a, b, c, d in faces] + [(a, c, d) for a, b, c, d in faces]
    return s * half, np.array(T)


def _revolution_mesh(profile: np.ndarray, n: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A closed surface of revolution about z from ``profile`` (k, 2) rows (radius, z)."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = [[r * np.cos(a), r * np.sin(a), z] for r, z in profile for a in t]
    T = []
    for i in range(len(profile) - 1):
        for j in range(n):
            a, b = i * n + j, i * n + (j + 1) % n
            T += [(a, b, b + n), (a, b + n, a + n)]
    V = np.array(V, dtype=float)
    # caps (fans around the first and last rings' centres)
    k = len(V)
    V = np.vstack([V, [0, 0, profile[0][1]], [0, 0, profile[-1][1]]])
    last = (len(profile) - 1) * n
    for j in range(n):
        T += [(k, (j + 1) % n, j), (k + 1, last + j, last + (j + 1) % n)]
    return V, np.array(T)


def shape_mesh(geometry: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Vertices (n, 3) and triangles (m, 3) of a coal geometry (meshes and the usual
    primitives), in its own frame; None for a geometry it cannot draw."""
    import coal

    if hasattr(geometry, "num_tris") and hasattr(geometry, "tri_indices"):
        n = int(geometry.num_tris)
        if n == 0:
            return None
        V = np.asarray(geometry.vertices(), dtype=float)
        T = np.array([(t[0], t[1], t[2]) for t in map(geometry.tri_indices, range(n))])
        return V, T
    if isinstance(geometry, coal.Box):
        return _box_mesh(np.asarray(geometry.halfSide, dtype=float))
    if isinstance(geometry, coal.Cylinder):
        r, h = float(geometry.radius), float(geometry.halfLength)
        return _revolution_mesh(np.array([[r, -h], [r, h]]))
    if isinstance(geometry, coal.Sphere | coal.Capsule):
        r = float(geometry.radius)
        h = float(getattr(geometry, "halfLength", 0.0))
        a = np.linspace(-np.pi / 2, np.pi / 2, 9)[1:-1]
        lower = [(r * np.cos(x), -h + r * np.sin(x)) for x in a if x < 0]
        upper = [(r * np.cos(x), h + r * np.sin(x)) for x in a if x >= 0]
        return _revolution_mesh(np.array([*lower, *upper]))
    return None


@dataclass(frozen=True)
class MeshPart:
    """One geometry object: its decimated mesh in its own frame, and where that frame is."""

    name: str
    joint_id: int  # Pinocchio parent joint
    placement: np.ndarray  # (4, 4) geometry frame in the joint frame
    vertices: np.ndarray  # (n, 3) [m]
    triangles: np.ndarray  # (m, 3)


@dataclass(frozen=True)
class RobotMeshes:
    """A posture's robot model and its decimated meshes."""

    model: pin.Model
    parts: tuple[MeshPart, ...]
    kind: str
    skipped: tuple[str, ...] = ()  # geometry objects it cannot draw

    @property
    def triangle_count(self) -> int:
        """Number of triangles over all parts."""
        return sum(len(p.triangles) for p in self.parts)


_MESH_CACHE_VERSION = 2
_GLTF_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # Rx(+90°)


def mesh_cache_dir() -> Path:
    """Where decimated meshes are cached: $POSTUREGEN_CACHE/meshes, else
    ~/.cache/posturegen/meshes (the proxies' cache root)."""
    root = os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen"
    return Path(root) / "meshes"


def _cache_file(urdf: str, package_dirs: tuple[str, ...], kind: str, cell: float) -> Path:
    import hashlib

    h = hashlib.sha256(Path(urdf).read_bytes())
    h.update(json.dumps([_MESH_CACHE_VERSION, urdf, package_dirs, kind, cell]).encode())
    return mesh_cache_dir() / f"{Path(urdf).stem}-{kind}-{h.hexdigest()[:16]}.npz"


def _load_parts(file: Path) -> tuple[list[MeshPart], list[str]] | None:
    try:
        with np.load(file, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            parts = [
                MeshPart(m["name"], m["joint"], z[f"P{i}"], z[f"V{i}"], z[f"T{i}"])
                for i, m in enumerate(meta["parts"])
            ]
            return parts, list(meta["skipped"])
    except (OSError, KeyError, ValueError):
        return None


def _save_parts(file: Path, parts: list[MeshPart], skipped: list[str]) -> None:
    meta = {"parts": [{"name": p.name, "joint": p.joint_id} for p in parts], "skipped": skipped}
    arrays: dict[str, Any] = {"meta": np.array(json.dumps(meta))}
    for i, p in enumerate(parts):
        arrays |= {f"P{i}": p.placement, f"V{i}": p.vertices, f"T{i}": p.triangles}
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        tmp = file.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(file)
    except OSError:  # a read-only cache only costs time
        pass


@functools.lru_cache(maxsize=4)
def _robot_meshes(urdf: str, package_dirs: tuple[str, ...], kind: str, cell: float) -> RobotMeshes:
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    file = _cache_file(urdf, package_dirs, kind, cell)
    cached = _load_parts(file) if file.is_file() else None
    if cached is not None:
        return RobotMeshes(model, tuple(cached[0]), kind, tuple(cached[1]))
    gtype = pin.GeometryType.VISUAL if kind == "visual" else pin.GeometryType.COLLISION
    try:
        gmodel = pin.buildGeomFromUrdf(model, urdf, gtype, package_dirs=list(package_dirs))
    except ValueError as exc:
        other = "collision" if kind == "visual" else "visual"
        raise InputError(
            "robot.package_dirs",
            f"cannot load the {kind} meshes of {urdf}: {exc}",
            f"give the folders that hold the meshes, or use --meshes {other}",
        ) from exc
    parts, skipped = [], []
    for obj in gmodel.geometryObjects:
        mesh = shape_mesh(obj.geometry)
        if mesh is None:
            skipped.append(obj.name)
            continue
        V, T = mesh
        if Path(str(obj.meshPath)).suffix.lower() in (".gltf", ".glb"):
            V = V @ _GLTF_TO_Z_UP.T  # glTF is y-up (as Drake reads it); assimp keeps it raw
        V, T = decimate(V, T, cell)
        if len(T):
            P = obj.placement.homogeneous
            parts.append(MeshPart(obj.name, int(obj.parentJoint), P, V, T.astype(np.int32)))
    _save_parts(file, parts, skipped)
    return RobotMeshes(model, tuple(parts), kind, tuple(skipped))


def robot_meshes(
    posture: dict[str, Any], kind: str = "visual", cell: float = PNG_CELL
) -> RobotMeshes:
    """The model and decimated meshes of a posture's robot (cached in memory and on disk, per
    URDF content, package folders, kind and cell)."""
    if kind not in MESH_KINDS:
        raise InputError("meshes", f"unknown kind '{kind}'", f"use one of {', '.join(MESH_KINDS)}")
    robot = posture["robot"]
    urdf = Path(str(robot.get("urdf", "")))
    if not urdf.is_file():
        raise InputError("robot.urdf", f"no file {urdf}", "regenerate the posture on this machine")
    dirs = tuple(str(p) for p in robot.get("package_dirs") or [])
    return _robot_meshes(str(urdf.resolve()), dirs, kind, float(cell))


# --------------------------------------------------------------------------- what to draw
def _se3(m: Any, where: str) -> np.ndarray:
    T = np.asarray(m, dtype=float)
    if T.shape != (4, 4):
        raise InputError(where, f"expected a 4x4 matrix, got shape {T.shape}", "a posture file")
    return T


def _apply(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return np.asarray(pts, dtype=float) @ T[:3, :3].T + T[:3, 3]


def _lift(pts2d: np.ndarray) -> np.ndarray:
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
            _apply(T, part.vertices)[part.triangles]
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
        T = _se3(s["placement"], f"surfaces[{s.get('name')}].placement")
        verts = np.asarray(s["vertices"], dtype=float)
        surfaces.setdefault(s["name"], (s["name"], T, verts, float(s.get("thickness", SLAB))))
    obstacles = [
        (
            str(o.get("name", "")),
            np.asarray(o["box"]["size"], dtype=float),
            _se3(o["box"]["placement"], "obstacles.box.placement"),
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
    T_ws = _se3(c["surface"]["placement"], f"{where}.surface.placement")
    rp = c["robot_patch"]
    if not model.existFrame(rp["frame"]):
        raise InputError(
            f"{where}.robot_patch.frame", f"no frame '{rp['frame']}'", "a posture of this URDF"
        )
    T_wf = data.oMf[model.getFrameId(rp["frame"])].homogeneous
    T_wp = T_wf @ _se3(rp["placement"], f"{where}.robot_patch.placement")
    patch3d = _apply(T_wp, _lift(rp["vertices"]))
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


# --------------------------------------------------------------------------- camera, z-buffer
def _view_direction(azim: float, elev: float) -> np.ndarray:
    """The unit vector from the scene towards a camera at azimuth and elevation [deg]."""
    a, e = np.radians(azim), np.radians(elev)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _base_yaw(posture: dict[str, Any]) -> float:
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


# --------------------------------------------------------------------------- scene geometry
def _clip_polygon(poly2d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """A convex polygon clipped to the rectangle [lo, hi] (shapely), None when empty."""
    from shapely.geometry import Polygon, box

    inter = Polygon(poly2d).intersection(box(lo[0], lo[1], hi[0], hi[1]))
    if inter.is_empty or inter.geom_type != "Polygon" or inter.area <= 0:
        return None
    return np.asarray(inter.exterior.coords)[:-1]


def _local_rect(T: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rectangle of a surface's plane (its frame) that covers the world box [lo, hi]."""
    corners = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    local = (corners - T[:3, 3]) @ T[:3, :3]
    return local[:, :2].min(axis=0), local[:, :2].max(axis=0)


def _surface_edges(
    T: np.ndarray, verts: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> list[np.ndarray]:
    """The pieces (2, 3) of a surface polygon's edges inside the world box [lo, hi]."""
    from shapely.geometry import LineString, box

    rlo, rhi = _local_rect(T, lo, hi)
    window = box(rlo[0], rlo[1], rhi[0], rhi[1])
    edges = []
    for i in range(len(verts)):
        piece = LineString([verts[i], verts[(i + 1) % len(verts)]]).intersection(window)
        if piece.geom_type == "LineString" and piece.length > 0:
            edges.append(_apply(T, _lift(np.asarray(piece.coords))))
    return edges


BIG_SURFACE = 1.5  # [m]: a surface this wide (ground, wall) is drawn as a plane, a smaller
# one (step, rung, rail) as the solid under it, ``thickness`` deep


def _scene_mesh(
    sv: StanceView, window: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World triangles of the scene: the surfaces (k, 3, 3) with their colours (k, 3) (in
    contact tinted red; a big surface clipped to the world box ``window`` when given, a small
    one with the sides of its solid, darker), and the obstacles' boxes (m, 3, 3)."""
    tris, cols = [], []
    in_contact = {c.surface for c in sv.contacts}
    for name, T, verts, thickness in sv.surfaces:
        rgb = np.array(CONTACT_SURFACE_RGB if name in in_contact else SCENE_RGB)
        small = float(np.ptp(verts, axis=0).max()) < BIG_SURFACE
        poly = verts if small or window is None else _clip_polygon(verts, *_local_rect(T, *window))
        if poly is None:
            continue
        top = _lift(poly)
        fan = _fan(len(top))
        tris.append(_apply(T, top[fan]))
        cols += [rgb] * len(fan)
        if small:
            bottom = top - [0, 0, thickness]
            tris.append(_apply(T, bottom[fan[:, ::-1]]))
            cols += [rgb] * len(fan)
            for i in range(len(top)):
                j = (i + 1) % len(top)
                quad = np.array([top[i], top[j], bottom[j], bottom[i]])
                tris.append(_apply(T, quad[[[0, 2, 1], [0, 3, 2]]]))
                cols += [0.8 * rgb] * 2
    boxes = []
    for _, size, T in sv.obstacles:
        V, F = _box_mesh(size / 2)
        boxes.append(_apply(T, V)[F])
    return (
        np.concatenate(tris) if tris else np.zeros((0, 3, 3)),
        np.array(cols, dtype=float).reshape(-1, 3),
        np.concatenate(boxes) if boxes else np.zeros((0, 3, 3)),
    )


def _fan(n: int) -> np.ndarray:
    """Triangles (n - 2, 3) of a fan over a convex polygon of n vertices."""
    return np.array([[0, i, i + 1] for i in range(1, n - 1)])


def _bounds(sv: StanceView, robot: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The world box the viewer frames: :func:`_content` and the obstacles near it."""
    allp = _content(sv, robot, scale)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    centre = (lo + hi) / 2
    for _, size, T in sv.obstacles:
        if np.all(np.abs(T[:3, 3] - centre) < (hi - lo) / 2 + 0.6):
            V = _apply(T, _box_mesh(size / 2)[0])
            lo, hi = np.minimum(lo, V.min(axis=0)), np.maximum(hi, V.max(axis=0))
    return lo, hi


def _force_scale(views: Sequence[StanceView]) -> float:
    """Metres of arrow per newton: the largest force point drawn 0.25 m long (at most the
    robot's weight drawn 1 m long)."""
    fmax = max(
        (
            float(np.linalg.norm(c.forces3d, axis=1).max())
            for sv in views
            for c in sv.contacts
            if len(c.forces3d)
        ),
        default=0.0,
    )
    weight = max(sv.weight for sv in views) if views else 1.0
    return min(0.25 / fmax if fmax > 0 else 0.0, 1.0 / max(weight, 1e-9))


# --------------------------------------------------------------------------- figure (PNG)
SUPERSAMPLE = 2  # pixels per figure pixel on each side (antialiasing)
OUTLINE_DEPTH = 0.025  # [m]: a depth step drawn as an outline


def _shade(
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


def _content(sv: StanceView, robot: np.ndarray, scale: float) -> np.ndarray:
    """World points (k, 3) the view must show: the robot, every contact (polygons, ellipse,
    force arrows), the surfaces of the contacts that are not big, the targets."""
    pts = [robot.reshape(-1, 3)]
    for c in sv.contacts:
        pts.append(c.patch3d)
        if c.ellipse3d is not None:
            pts.append(c.ellipse_points(16))
        if len(c.points3d):
            pts += [c.points3d, c.points3d + scale * c.forces3d]
        if float(np.ptp(c.surface2d, axis=0).max()) < BIG_SURFACE:
            pts.append(_apply(c.T_ws, _lift(c.surface2d)))
    pts += [t[None] for _, t in sv.targets]
    return np.vstack(pts)


def _around_contacts(sv: StanceView, reach: float = 0.1, n: int = 7) -> np.ndarray:
    """World points (k, 3) on each contact's surface around its robot patch (``reach`` [m]
    beyond it), lifted 2 mm off the surface: what a view of the contact should not hide."""
    from shapely.geometry import Point, Polygon

    out = []
    for c in sv.contacts:
        lo, hi = c.patch2d.min(axis=0) - reach, c.patch2d.max(axis=0) + reach
        surface = Polygon(c.surface2d)
        grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n)))
        pts = [p for p in grid.reshape(2, -1).T if surface.covers(Point(p))]
        if pts:
            out.append(_apply(c.T_ws, _lift(np.array(pts)) + [0, 0, 0.002]))
    return np.vstack(out) if out else np.zeros((0, 3))


def _choose_camera(
    sv: StanceView, robot: np.ndarray, scene: np.ndarray, content: np.ndarray, elevation: float
) -> Camera:
    """The first of :data:`VIEW_AZIMUTHS` whose score is (nearly) the best one's. The score,
    from low-resolution z-buffers: the part of the robot the scene leaves visible, plus the
    part of the contacts' surfaces around the contacts that the rest of the scene leaves
    visible, plus half the part of the contacts whose surface faces the camera."""
    heading = _base_yaw(sv.posture)
    normals = np.array([c.T_ws[:3, 2] for c in sv.contacts]).reshape(-1, 3)
    around = _around_contacts(sv)
    robot = robot[:: max(1, len(robot) // 15000)]  # a sample is enough for a fraction
    tris = np.concatenate([robot, scene])
    nr, size = len(robot), 128
    top = 1.0 + (1.0 if len(around) else 0.0) + (0.5 if len(normals) else 0.0)  # best possible
    scores = []
    for azim in VIEW_AZIMUTHS:
        cam = Camera.orbit(heading + azim, elevation)
        frame = Frame.fit(cam.screen(content), size, size)
        P, Z = frame.pixels(cam.screen(tris)), cam.depth(tris)
        alone = (rasterize(P[:nr], Z[:nr], size, size)[1] >= 0).sum()
        ids = rasterize(P, Z, size, size)[1]
        robot_seen = ((ids >= 0) & (ids < nr)).sum() / max(alone, 1)
        score = float(robot_seen)
        if len(around):
            zbuf = rasterize(P[nr:], Z[nr:], size, size)[0]
            score += float(np.mean(_visible(cam, frame, zbuf, around)))
        if len(normals):
            score += 0.5 * float(np.mean(normals @ -cam.forward > 0.05))
        scores.append(score)
        if score >= top - 0.05:  # no later candidate can beat it by more
            break
    best = max(scores)
    azim = next(a for a, s in zip(VIEW_AZIMUTHS, scores, strict=False) if s >= best - 0.05)
    return Camera.orbit(heading + azim, elevation)


def _image(
    cam: Camera,
    frame: Frame,
    robot: np.ndarray,
    scene: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, Frame]:
    """The shaded view of the robot and the scene (:func:`_scene_mesh`) as RGB floats
    (frame.height, frame.width, 3), the depth image of the supersampled frame, and that
    frame."""
    big = frame.scaled(SUPERSAMPLE)
    surfaces, surface_rgb, boxes = scene
    tris = np.concatenate([robot, surfaces])
    base = np.vstack([np.tile(ROBOT_RGB, (len(robot), 1)), surface_rgb])
    flat = np.r_[np.zeros(len(robot)), np.full(len(surfaces), 0.6)]
    colours = np.vstack([_shade(tris, base, cam, flat), np.ones((1, 3))])  # last: background
    zbuf, ids = rasterize(big.pixels(cam.screen(tris)), cam.depth(tris), big.width, big.height)
    img = colours[ids]  # -1: the background
    # outlines: depth steps, and the robot's edge against the scene, on the nearer side
    kind = np.where(ids < 0, 0, np.where(ids < len(robot), 1, 2))
    edge = np.zeros(ids.shape, dtype=bool)
    for axis in (0, 1):
        z, k, e = (np.moveaxis(a, axis, 0) for a in (zbuf, kind, edge))
        with np.errstate(invalid="ignore"):
            step = (np.abs(z[1:] - z[:-1]) > OUTLINE_DEPTH) | (k[1:] != k[:-1])
        near = z[1:] < z[:-1]
        e[1:] |= step & near
        e[:-1] |= step & ~near
    img[edge & (ids >= 0)] *= 0.45
    if len(boxes):  # obstacles: translucent, over what they hide
        bz, bids = rasterize(big.pixels(cam.screen(boxes)), cam.depth(boxes), big.width, big.height)
        front = (bids >= 0) & (bz < zbuf)
        shade = _shade(boxes, np.tile(OBSTACLE_RGB, (len(boxes), 1)), cam)
        img[front] = 0.35 * img[front] + 0.65 * shade[bids[front]]
    k = SUPERSAMPLE
    return img.reshape(frame.height, k, frame.width, k, 3).mean(axis=(1, 3)), zbuf, big


def _visible(cam: Camera, frame: Frame, zbuf: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Whether world points (k, 3) are in front of the z-buffer of ``frame`` (or outside it),
    within 1 cm and 3 pixels."""
    px = np.floor(frame.pixels(cam.screen(pts))).astype(np.int64)
    inside = (px[:, 0] >= 0) & (px[:, 0] < frame.width) & (px[:, 1] >= 0)
    inside &= px[:, 1] < frame.height
    z = np.full(len(pts), np.inf)
    z[inside] = zbuf[px[inside, 1], px[inside, 0]]
    return cam.depth(pts) <= z + 0.01 + 3 * frame.res


def _draw_edges(
    ax: Any, cam: Camera, big: Frame, zbuf: np.ndarray, seg: np.ndarray, color: str
) -> None:
    """An edge (2, 3): solid where seen, dotted where hidden."""
    n = max(2, int(np.linalg.norm(np.diff(cam.screen(seg), axis=0)) / big.res / 2))
    pts = seg[0] + np.linspace(0, 1, n)[:, None] * (seg[1] - seg[0])
    xy = cam.screen(pts)
    seen = _visible(cam, big, zbuf, pts)
    for flag in (True, False):
        y = xy.copy()
        y[seen != flag] = np.nan  # runs of one kind
        if np.isfinite(y).any():
            style = {"lw": 1.6, "ls": "-"} if flag else {"lw": 0.9, "ls": (0, (2, 2))}
            ax.plot(y[:, 0], y[:, 1], color=color, zorder=4, **style)


@dataclass(frozen=True)
class View3D:
    """What the figure's 3-D view draws: the robot's world triangles, the points it must show,
    the scene (:func:`_scene_mesh`, big surfaces clipped to ``box``) and the camera."""

    sv: StanceView
    scale: float  # force arrows [m/N]
    robot: np.ndarray
    content: np.ndarray
    box: tuple[np.ndarray, np.ndarray]
    scene: tuple[np.ndarray, np.ndarray, np.ndarray]
    cam: Camera

    @classmethod
    def of(
        cls,
        sv: StanceView,
        scale: float,
        azimuth: float | None = None,
        elevation: float = VIEW_ELEVATION,
    ) -> View3D:
        """The view of a stance (see :func:`render_png` for the camera)."""
        robot = sv.world_triangles()
        content = _content(sv, robot, scale)
        lo, hi = content.min(axis=0), content.max(axis=0)
        margin = 0.35 + 0.1 * float((hi - lo).max())
        box = (lo - margin, hi + margin)  # where big surfaces (ground, walls) are drawn
        scene = _scene_mesh(sv, box)
        if azimuth is None:
            cam = _choose_camera(sv, robot, scene[0], content, elevation)
        else:
            cam = Camera.orbit(_base_yaw(sv.posture) + azimuth, elevation)
        return cls(sv, scale, robot, content, box, scene, cam)

    @property
    def aspect(self) -> float:
        """Width / height of the content on the screen."""
        span = np.ptp(self.cam.screen(self.content), axis=0)
        return float(span[0] / max(span[1], 1e-9))


def _draw_3d(ax: Any, view: View3D, width: int, height: int) -> None:
    """The robot, the scene and the contacts, orthographic, on a 2-D axes of ``width`` x
    ``height`` pixels: a z-buffered image of the meshes, the contacts drawn on top."""
    from matplotlib.patches import FancyArrowPatch, Polygon

    sv, scale, cam, box = view.sv, view.scale, view.cam, view.box
    frame = Frame.fit(cam.screen(view.content), width, height, margin=0.03)
    img, zbuf, big = _image(cam, frame, view.robot, view.scene)
    ax.imshow(img, extent=frame.extent, interpolation="none", zorder=1)

    drawn = set()
    for c in sv.contacts:  # the contacts' surfaces' edges, hidden parts dotted
        if c.surface not in drawn:
            drawn.add(c.surface)
            for seg in _surface_edges(c.T_ws, c.surface2d, *box):
                _draw_edges(ax, cam, big, zbuf, seg, SURFACE_COLOR)
    for _, size, T in sv.obstacles:  # the obstacles' edges
        corners = _apply(T, _box_mesh(size / 2)[0])
        for i, j in _BOX_EDGES:
            _draw_edges(ax, cam, big, zbuf, corners[[i, j]], OBSTACLE_EDGE_COLOR)
    for c in sv.contacts:  # on top of everything
        ax.add_patch(
            Polygon(
                cam.screen(c.patch3d), closed=True, fc=PATCH_COLOR, alpha=0.35, ec="none", zorder=5
            )
        )
        ax.add_patch(
            Polygon(
                cam.screen(c.patch3d), closed=True, fill=False, ec=PATCH_COLOR, lw=1.6, zorder=5
            )
        )
        E = c.ellipse_points()
        if E is not None:
            ax.add_patch(
                Polygon(
                    cam.screen(E),
                    closed=True,
                    fc=ELLIPSE_COLOR,
                    alpha=0.4,
                    ec=ELLIPSE_COLOR,
                    lw=1.6,
                    zorder=6,
                )
            )
        if c.point3d is not None:
            ax.plot(*cam.screen(c.point3d), "o", color=PATCH_COLOR, ms=5, zorder=7)
        if len(c.forces3d) and scale > 0:
            a = cam.screen(c.points3d)
            b = cam.screen(c.points3d + scale * c.forces3d)
            for p, q in zip(a, b, strict=True):
                ax.add_patch(
                    FancyArrowPatch(
                        p,
                        q,
                        arrowstyle="-|>",
                        mutation_scale=9,
                        color=FORCE_COLOR,
                        lw=1.4,
                        shrinkA=0,
                        shrinkB=0,
                        zorder=8,
                    )
                )
            ax.plot(*a.T, "o", color=FORCE_COLOR, ms=2.5, zorder=8)
        centre = cam.screen(c.patch3d.mean(axis=0))
        ax.annotate(
            c.name,
            centre,
            xytext=(10, -12),
            textcoords="offset points",
            fontsize=8,
            color="#1b5e20",
            zorder=9,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7},
        )
    for _, t in sv.targets:
        ax.plot(*cam.screen(t), "x", color="black", ms=8, mew=2, zorder=9)
    ax.set_xlim(frame.extent[0], frame.extent[1])
    ax.set_ylim(frame.extent[2], frame.extent[3])
    ax.set_aspect("equal")
    ax.set_axis_off()


def _view_rect(c: ContactView) -> tuple[np.ndarray, np.ndarray]:
    """The close-up's window (surface frame): the patch, the ellipse and the force points,
    with a margin."""
    pts = [c.patch2d]
    E = c.ellipse_points()
    if E is not None:
        pts.append(c.to_surface(E))
    if len(c.points3d):
        pts.append(c.to_surface(c.points3d))
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    m = 0.2 * float((hi - lo).max()) + 0.01
    return lo - m, hi + m


def _draw_closeup(ax: Any, c: ContactView, scale2d: float) -> None:
    """One contact in its surface's plane: both polygons, their intersection, the ellipse and
    the force points (normal force in N, tangential part as an arrow)."""
    from matplotlib.patches import Polygon as MplPolygon
    from shapely.geometry import Polygon

    lo, hi = _view_rect(c)
    box = ax.get_position()  # widen the window to the cell's shape: more of the surroundings
    shape = box.width * ax.figure.bbox.width / (box.height * ax.figure.bbox.height)
    centre, span = (lo + hi) / 2, hi - lo
    span = np.maximum(span, [span[1] * shape, span[0] / shape])
    lo, hi = centre - span / 2, centre + span / 2
    surf = _clip_polygon(c.surface2d, lo - 1.0, hi + 1.0)
    if surf is not None:
        ax.add_patch(MplPolygon(surf, closed=True, fc=SURFACE_COLOR, alpha=0.12, ec="none"))
        ax.add_patch(MplPolygon(surf, closed=True, fill=False, ec=SURFACE_COLOR, lw=2))
    ax.add_patch(MplPolygon(c.patch2d, closed=True, fc=PATCH_COLOR, alpha=0.15, ec="none"))
    ax.add_patch(MplPolygon(c.patch2d, closed=True, fill=False, ec=PATCH_COLOR, lw=2))
    inter = Polygon(c.patch2d).intersection(Polygon(c.surface2d))
    info = []
    if not inter.is_empty and inter.geom_type == "Polygon" and inter.area > 0:
        I = np.asarray(inter.exterior.coords)[:-1]
        ax.add_patch(
            MplPolygon(I, closed=True, fill=False, ec="0.35", lw=0.8, ls="--", hatch="///")
        )
        info.append(f"P1∩P2 {1e4 * inter.area:.0f} cm²")
    E = c.ellipse_points(180)
    if E is not None:
        e2 = c.to_surface(E)
        ax.fill(e2[:, 0], e2[:, 1], color=ELLIPSE_COLOR, alpha=0.18, lw=0)
        ax.plot(*np.vstack([e2, e2[:1]]).T, color=ELLIPSE_COLOR, lw=2)
        centre = c.to_surface(c.ellipse3d[0][None])[0]
        ax.plot(*centre, "+", color=ELLIPSE_COLOR, ms=8)
        r1, r2 = (float(np.linalg.norm(a)) for a in c.ellipse3d[1:])
        info.append(f"ellipse {100 * r1:.1f}×{100 * r2:.1f} cm")
    if c.point3d is not None:
        ax.plot(*c.to_surface(c.point3d[None])[0], "o", color=PATCH_COLOR, ms=6)
    if len(c.points3d):
        p2 = c.to_surface(c.points3d)
        R = c.T_ws[:3, :3]
        local = c.forces3d @ R  # surface frame components
        fn = local[:, 2]
        ax.scatter(
            p2[:, 0],
            p2[:, 1],
            s=18 + 60 * fn / max(fn.max(), 1e-9),
            color=FORCE_COLOR,
            zorder=5,
            edgecolors="white",
            linewidths=0.5,
        )
        if scale2d > 0:
            ax.quiver(
                p2[:, 0],
                p2[:, 1],
                local[:, 0] * scale2d,
                local[:, 1] * scale2d,
                color=FORCE_COLOR,
                angles="xy",
                scale_units="xy",
                scale=1,
                width=0.006,
                zorder=6,
            )
        centre = p2.mean(axis=0)
        for p, f in zip(p2, fn, strict=True):
            if f > max(0.05 * fn.max(), 0.5):  # [N]
                u = p - centre  # the label outwards, away from the other points
                u = u / n if (n := float(np.linalg.norm(u))) > 1e-9 else np.array([1.0, 1.0])
                ax.annotate(
                    f"{f:.0f} N",
                    p,
                    textcoords="offset points",
                    xytext=tuple(9 * u),
                    ha="left" if u[0] > 0.3 else ("right" if u[0] < -0.3 else "center"),
                    va="bottom" if u[1] > 0.3 else ("top" if u[1] < -0.3 else "center"),
                    fontsize=7.5,
                    color="#900000",
                    zorder=7,
                )
        info.append(f"Σfₙ {fn.sum():.0f} N")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.25)
    ax.set_title(
        f"{c.name} ({c.type}) on {c.surface}" + ("\n" + ", ".join(info) if info else ""), fontsize=9
    )
    ax.set_xlabel("x in the surface plane [m]", fontsize=7)
    ax.set_ylabel("y [m]", fontsize=7)


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
    """Draw a posture (file path or dict) to a PNG: the 3-D view on the left, a close-up of
    each contact in its own plane on the right. 1600 x 900 pixels at ``dpi`` 100.

    The camera looks from ``azimuth`` degrees off the robot's heading (default: the first of
    :data:`VIEW_AZIMUTHS` that hides little of the robot behind the scene), ``elevation``
    degrees above the horizon."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    data = load_posture_any(posture)
    sv = stance_view(data, meshes, PNG_CELL)
    scale = _force_scale([sv])
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
    _draw_3d(ax3, view, width, height)
    for k, c in enumerate(sv.contacts):
        ax = fig.add_subplot(gs[k // ncols, 1 + k % ncols])
        _draw_closeup(ax, c, 0.5 * scale)
    if title is None:
        title = _title(data, Path(posture).name if isinstance(posture, str | Path) else None)
    fig.suptitle(title, fontsize=13)
    handles = [
        Patch(fc=PATCH_COLOR, alpha=0.5, ec=PATCH_COLOR, label="robot patch (P1)"),
        Patch(fc=SURFACE_COLOR, alpha=0.3, ec=SURFACE_COLOR, label="surface (P2)"),
        Patch(fc=ELLIPSE_COLOR, alpha=0.4, ec=ELLIPSE_COLOR, label="contact ellipse"),
        Line2D(
            [],
            [],
            color=FORCE_COLOR,
            lw=2,
            label=f"contact force ({0.1 / scale:.0f} N per 10 cm)"
            if scale > 0
            else "contact force",
        ),
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
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, format="png")
    return out


# --------------------------------------------------------------------------- viewer (HTML)
def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _rounded(a: np.ndarray, digits: int = 5) -> list[Any]:
    return np.round(np.asarray(a, dtype=float), digits).tolist()


def _scene_blob(sv: StanceView) -> dict[str, Any]:
    """The stance's surfaces (:func:`_scene_mesh`, unclipped) and obstacles as world triangle
    soups: base64 float32 positions, uint8 RGB per vertex for the surfaces."""
    surfaces, rgb, boxes = _scene_mesh(sv)
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
        "surface": _rounded(_apply(c.T_ws, _lift(c.surface2d))),
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


def viewer_html(views: Sequence[StanceView], files: Sequence[str], title: str) -> str:
    """The viewer's HTML text for stances of one robot (their meshes are the first one's)."""
    meshes = views[0].meshes
    mesh_json = []
    for p in meshes.parts:
        wide = len(p.vertices) > 65535
        mesh_json.append(
            {
                "name": p.name,
                "v": _b64(p.vertices.astype("<f4")),
                "i": _b64(p.triangles.astype("<u4" if wide else "<u2")),
                "wide": wide,
            }
        )
    scenes: list[dict[str, Any]] = []
    stages = []
    scale = _force_scale(views)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for sv, file in zip(views, files, strict=True):
        blob = _scene_blob(sv)
        if blob not in scenes:
            scenes.append(blob)
        b_lo, b_hi = _bounds(sv, sv.world_triangles(), scale)
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
        "view": {"target": _rounded(centre), "eye": _rounded(eye)},
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
