"""Pictures of posture files: a paper-style figure (PNG) and a self-contained 3D viewer (HTML).

- :func:`render_png` draws a posture as in the paper's figures 1, 6 and 7: the robot with its
  meshes, the scene's surfaces and obstacles, each contact's polygons (robot patch green,
  surface red), its ellipse (blue) and its forces (red arrows); beside it a close-up of each
  contact in its surface's plane (both polygons, their intersection, the ellipse, the force
  points). Matplotlib with the Agg canvas only: no display needed.
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
VIEW_AZIMUTH = -35.0  # the camera, from the robot's heading [deg] (front, robot's right side)
VIEW_ELEVATION = 18.0  # [deg]
PNG_CELL = 0.012  # decimation cell of the figure's meshes [m]
HTML_CELL = 0.006  # decimation cell of the viewer's meshes [m]
SLAB = 0.02  # thickness of a surface's solid when the posture file does not give it [m]

ROBOT_RGB = (0.70, 0.72, 0.75)
PATCH_COLOR = "#1a9a3a"  # robot patch: green
SURFACE_COLOR = "#d62728"  # surface polygon: red
ELLIPSE_COLOR = "#1f3fd0"  # contact ellipse: blue
FORCE_COLOR = "#e00000"  # contact forces: red arrows
SCENE_RGB = (0.86, 0.80, 0.68)  # support surfaces
CONTACT_SURFACE_RGB = (0.92, 0.74, 0.66)  # support surfaces in contact (tinted red)
OBSTACLE_RGB = (0.62, 0.70, 0.80)


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


# --------------------------------------------------------------------------- figure (PNG)
def _view_direction(azim: float, elev: float) -> np.ndarray:
    a, e = np.radians(azim), np.radians(elev)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _base_yaw(posture: dict[str, Any]) -> float:
    x, y, z, w = np.asarray(posture["q"][3:7], dtype=float)
    return math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _clip_polygon(poly2d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """A convex polygon clipped to the rectangle [lo, hi] (shapely), None when empty."""
    from shapely.geometry import Polygon, box

    inter = Polygon(poly2d).intersection(box(lo[0], lo[1], hi[0], hi[1]))
    if inter.is_empty or inter.geom_type != "Polygon" or inter.area <= 0:
        return None
    return np.asarray(inter.exterior.coords)[:-1]


def _tiles(poly2d: np.ndarray, step: float) -> list[np.ndarray]:
    """Triangles (k, 3, 2) covering a convex polygon, cut on a grid of ``step`` so that the
    painter's algorithm sorts them sensibly among the robot's triangles."""
    from shapely.geometry import Polygon, box

    P = Polygon(poly2d)
    x0, y0, x1, y1 = P.bounds
    out = []
    for x in np.arange(x0, x1, step):
        for y in np.arange(y0, y1, step):
            cell = P.intersection(box(x, y, min(x + step, x1), min(y + step, y1)))
            if cell.is_empty or cell.geom_type != "Polygon" or cell.area <= 1e-12:
                continue
            v = np.asarray(cell.exterior.coords)[:-1]
            out += [np.array([v[0], v[i], v[i + 1]]) for i in range(1, len(v) - 1)]
    return out


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


def _quad_tiles(a: np.ndarray, b: np.ndarray, d: np.ndarray, step: float) -> list[np.ndarray]:
    """Triangles (3, 3) covering the parallelogram a, b, b + d - a, d, cut in cells of about
    ``step`` so that the painter's algorithm sorts them sensibly."""
    nu = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
    nv = max(1, math.ceil(float(np.linalg.norm(d - a)) / step))
    out = []
    for i in range(nu):
        for j in range(nv):
            p = [
                a + (b - a) * u / nu + (d - a) * v / nv
                for u, v in ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1))
            ]
            out += [np.array(p[:3]), np.array([p[0], p[2], p[3]])]
    return out


def _scene_triangles(
    sv: StanceView, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World triangles (k, 3, 3) and base colours (k, 3) of the surfaces (clipped to the box
    [lo, hi]; a small one with the sides of its solid) and the obstacles."""
    tris, cols = [], []
    in_contact = {c.surface for c in sv.contacts}
    for name, T, verts, thickness in sv.surfaces:
        clipped = _clip_polygon(verts, *_local_rect(T, lo, hi))
        if clipped is None:
            continue
        extent = float(np.ptp(clipped, axis=0).max())
        rgb = CONTACT_SURFACE_RGB if name in in_contact else SCENE_RGB
        for t in _tiles(clipped, max(extent / 10, 0.05)):
            tris.append(_apply(T, _lift(t)))
            cols.append(rgb)
        if float(np.ptp(verts, axis=0).max()) < 1.5:  # a step or a rung: its sides
            top = _lift(verts)
            bottom = top - [0, 0, thickness]
            for i in range(len(verts)):
                j = (i + 1) % len(verts)
                side = _quad_tiles(top[i], top[j], bottom[i], 0.1)
                tris += [_apply(T, t) for t in side]
                cols += [np.multiply(rgb, 0.85)] * len(side)
    faces = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    for _, size, T in sv.obstacles:
        V = _box_mesh(size / 2)[0]
        for face in faces:
            a, b, _, d = (V[i] for i in face)
            pieces = _quad_tiles(a, b, d, max(float(size.max()) / 4, 0.05))
            tris += [_apply(T, t) for t in pieces]
            cols += [OBSTACLE_RGB] * len(pieces)
    if not tris:
        return np.zeros((0, 3, 3)), np.zeros((0, 3))
    return np.array(tris), np.array(cols, dtype=float)


def _bounds(sv: StanceView, robot_tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box the 3-D view shows: robot, contacts, forces, targets, near obstacles."""
    pts = [robot_tris.reshape(-1, 3)]
    for c in sv.contacts:
        pts.append(c.patch3d)
        if c.ellipse3d is not None:
            pts.append(c.ellipse_points(8))
        if len(c.points3d):
            pts.append(c.points3d)
        # small surfaces (steps, rungs) entirely
        if np.ptp(c.surface2d, axis=0).max() < 1.5:
            pts.append(_apply(c.T_ws, _lift(c.surface2d)))
    pts += [t for _, t in sv.targets]
    allp = np.vstack([np.reshape(p, (-1, 3)) for p in pts])
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


def _draw_3d(ax: Any, sv: StanceView, scale: float) -> None:
    """The robot, the scene and the contacts on a 3-D axes (orthographic)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    robot = sv.world_triangles()
    lo, hi = _bounds(sv, robot)
    margin = 0.05 * float((hi - lo).max()) + 0.05
    lo, hi = lo - margin, hi + margin
    lo[2] = min(lo[2], robot.reshape(-1, 3)[:, 2].min() - 0.02)
    azim, elev = _base_yaw(sv.posture) + VIEW_AZIMUTH, VIEW_ELEVATION
    light = _view_direction(azim + 40.0, elev + 35.0)

    scene, scene_rgb = _scene_triangles(
        sv, lo - 0.25 * (hi - lo).max(), hi + 0.25 * (hi - lo).max()
    )
    tris = np.concatenate([robot, scene])
    base = (
        np.vstack([np.tile(ROBOT_RGB, (len(robot), 1)), scene_rgb])
        if len(scene)
        else np.tile(ROBOT_RGB, (len(robot), 1))
    )
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
    shade = 0.45 + 0.55 * np.abs(n @ light)
    colors = np.clip(base * shade[:, None], 0, 1)
    coll = Poly3DCollection(tris, facecolors=colors, edgecolors=colors, linewidths=0.25)
    coll.set_zorder(1)
    ax.add_collection3d(coll)

    overlay = 1e-3  # lift the contact drawings off their surface [m]
    clip_lo, clip_hi = lo - 0.25 * (hi - lo).max(), hi + 0.25 * (hi - lo).max()
    drawn = set()
    for c in sv.contacts:  # the edges of small surfaces (steps, rungs), drawn on top
        if c.surface in drawn or float(np.ptp(c.surface2d, axis=0).max()) >= 1.5:
            continue
        drawn.add(c.surface)
        for seg in _surface_edges(c.T_ws, c.surface2d, clip_lo, clip_hi):
            ax.plot(*(seg + overlay * c.T_ws[:3, 2]).T, color=SURFACE_COLOR, lw=1.6, zorder=5)
    for c in sv.contacts:
        normal = c.T_ws[:3, 2]
        P = c.patch3d + 2 * overlay * normal
        ax.add_collection3d(_poly3d(P, PATCH_COLOR, 0.25, 1.6, 6))
        E = c.ellipse_points()
        if E is not None:
            ax.add_collection3d(_poly3d(E + 3 * overlay * normal, ELLIPSE_COLOR, 0.35, 1.8, 7))
        if c.point3d is not None:
            ax.scatter(*c.point3d, color=PATCH_COLOR, s=20, zorder=8, depthshade=False)
        if len(c.forces3d) and scale > 0:
            v = c.forces3d * scale
            ax.quiver(
                *c.points3d.T,
                *v.T,
                color=FORCE_COLOR,
                linewidths=1.6,
                arrow_length_ratio=0.25,
                zorder=9,
                normalize=False,
            )
    for _, t in sv.targets:
        ax.scatter(*t, marker="x", color="black", s=40, zorder=10, depthshade=False)

    ax.computed_zorder = False
    ax.set_proj_type("ortho")
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo), zoom=1.3)
    ax.set_axis_off()


def _poly3d(pts: np.ndarray, color: str, alpha: float, lw: float, z: int) -> Any:
    from matplotlib.colors import to_rgba
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    p = Poly3DCollection(
        [pts],
        facecolors=[to_rgba(color, alpha)],
        edgecolors=[to_rgba(color, 1.0)],
        linewidths=lw,
    )
    p.set_zorder(z)
    return p


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
        for (x, y), f in zip(p2, fn, strict=True):
            if f > max(0.02 * fn.max(), 0.5):  # [N]
                ax.annotate(
                    f"{f:.0f} N",
                    (x, y),
                    textcoords="offset points",
                    xytext=(4, 4),
                    fontsize=7,
                    color="#900000",
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


def render_png(
    posture: str | Path | dict[str, Any],
    out_path: str | Path,
    *,
    meshes: str = "visual",
    dpi: float = 100.0,
    title: str | None = None,
) -> Path:
    """Draw a posture (file path or dict) to a PNG: the 3-D view on the left, a close-up of
    each contact in its own plane on the right. 1600 x 900 pixels at ``dpi`` 100."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    data = load_posture_any(posture)
    sv = stance_view(data, meshes, PNG_CELL)
    scale = _force_scale([sv])
    fig = Figure(figsize=(16, 9), dpi=dpi)
    FigureCanvasAgg(fig)
    n = len(sv.contacts)
    ncols = 0 if n == 0 else (1 if n <= 2 else 2)
    nrows = max(1, math.ceil(n / max(ncols, 1)))
    gs = fig.add_gridspec(
        nrows,
        1 + ncols,
        width_ratios=[1.8 if ncols == 1 else 2.3] + [1.0] * ncols,
        left=0.01,
        right=0.98,
        top=0.9,
        bottom=0.07,
        wspace=0.28,
        hspace=0.45,
    )
    ax3 = fig.add_subplot(gs[:, 0], projection="3d")
    _draw_3d(ax3, sv, scale)
    for k, c in enumerate(sv.contacts):
        ax = fig.add_subplot(gs[k // ncols, 1 + k % ncols])
        _draw_closeup(ax, c, 0.5 * scale)
    if title is None:
        src = Path(posture).name if isinstance(posture, str | Path) else "posture"
        robot = data["robot"].get("name", "robot")
        why = str(data.get("message", "?"))
        state = "verified" if data.get("success") else f"NOT verified: {why[:80]}"
        title = f"{robot} — {src} — {state}"
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
    """The stance's surfaces (fans; a small one as a slab) and obstacles as world triangle
    soups: base64 float32 positions, uint8 RGB per vertex for the surfaces."""
    in_contact = {c.surface for c in sv.contacts}
    tris, cols = [], []
    for name, T, verts, thickness in sv.surfaces:
        rgb = CONTACT_SURFACE_RGB if name in in_contact else SCENE_RGB
        top = _lift(verts)
        tris += [_apply(T, top[[0, i, i + 1]]) for i in range(1, len(top) - 1)]
        cols += [rgb] * (len(top) - 2)
        if float(np.ptp(verts, axis=0).max()) < 1.5:
            bottom = top - [0, 0, thickness]
            tris += [_apply(T, bottom[[0, i + 1, i]]) for i in range(1, len(top) - 1)]
            cols += [rgb] * (len(top) - 2)
            for i in range(len(top)):
                j = (i + 1) % len(top)
                quad = np.array([top[i], top[j], bottom[j], bottom[i]])
                tris += [_apply(T, quad[[0, 2, 1]]), _apply(T, quad[[0, 3, 2]])]
                cols += [np.multiply(rgb, 0.85)] * 2
    out: dict[str, Any] = {}
    if tris:
        rgb8 = np.repeat(np.round(255 * np.array(cols, dtype=float)), 3, axis=0)
        out["surfaces"] = {
            "v": _b64(np.array(tris).astype("<f4")),
            "c": _b64(rgb8.astype(np.uint8)),
        }
    boxes = []
    for _, size, T in sv.obstacles:
        V, F = _box_mesh(size / 2)
        boxes.append(_apply(T, V)[F])
    if boxes:
        out["obstacles"] = {"v": _b64(np.concatenate(boxes).astype("<f4"))}
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
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for sv, file in zip(views, files, strict=True):
        blob = _scene_blob(sv)
        if blob not in scenes:
            scenes.append(blob)
        robot = sv.world_triangles()
        b_lo, b_hi = _bounds(sv, robot)
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
    scale = _force_scale(views)
    centre = (lo + hi) / 2
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    eye = centre + 1.05 * radius / math.sin(math.radians(15)) * _view_direction(
        _base_yaw(views[0].posture) + VIEW_AZIMUTH, VIEW_ELEVATION
    )
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
