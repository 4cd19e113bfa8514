"""A posture's robot meshes: Pinocchio's GeometryModel (visual or collision), primitives
tessellated, decimated by vertex clustering on a grid of ``cell`` metres, cached in memory and
on disk ($POSTUREGEN_CACHE/meshes)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._cache import memoize
from ..errors import InputError
from .style import MESH_KINDS, PNG_CELL


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


BOX_EDGES = [(i, i ^ bit) for i in range(8) for bit in (1, 2, 4) if i < i ^ bit]  # of box_mesh


def box_mesh(half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
        return box_mesh(np.asarray(geometry.halfSide, dtype=float))
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


@memoize("robot meshes", 4)
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
