"""Joint-space maps of the self pairs that spheres cannot hold apart.

A pair whose proxies overlap at the reference posture while its meshes do not is held at its
reference clearance minus SLIDE (posturegen.collision.proxies): its sphere rows cannot tell
when its meshes meet. HRP-2 has four such pairs: each hip's yaw and pitch links (meshes
1.3 mm apart at the reference, proxies -15.6 mm) and each knee and ankle-roll link (3.0 mm,
-23.6 and -28.0 mm); their meshes met 20-80 mm deep in postures whose rows held.

When the placement of one link of such a pair relative to the other depends on two joints
only (the joints between them on the kinematic tree), its meshes meet on a fixed region of
those two joints' plane. The map samples that plane within the joint limits every MAP_STEP
[rad] with the meshes (coal), takes the cells within MAP_DELTA of a colliding one, and covers
them with discs (greedily, the deepest uncovered cell first, each disc reaching MAP_EXCESS past
the cells it covers). Each disc (c, ρ) is a row

    ((q_i - c_i)² + (q_j - c_j)²) / ρ² - 1 >= 0

(q_i, q_j the pair's two joint coordinates [rad]): smooth, and met only outside every disc,
where the meshes are at least MAP_DELTA (less a cell) from meeting in that plane. The mesh
check still decides; ``tests/test_joint_maps.py`` samples the plane and checks that no
posture meeting the rows has meshes that meet.

The rows are the robot's, whatever the problem (one structure), unbounded until the map is
held (:meth:`CollisionTerm.bounds`): from the start when its discs are MAP_FAR from the
reference posture, else as a sphere pair, once its joints come within MAP_ACTIVATION of a disc;
never for a pair the problem does not check (excluded, or placed by fixed contacts)."""

from __future__ import annotations

import hashlib
import importlib.resources
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
from scipy import ndimage

from .._cache import BoundedCache
from ..model.robot import Robot
from .proxies import ProxyModel, cache_dir

MAP_STEP = 0.01  # [rad] the grid of a map
MAP_DELTA = 0.03  # [rad] cells this near a colliding one are covered
MAP_EXCESS = 0.02  # [rad] a disc reaches this past the cells it covers
MAP_VERSION = 1
# [rad] a map's rows hold once the joints come this near one of its discs (at the first start,
# or inside one after a run: as the sphere pairs' activation); until then they are unbounded,
# and IPOPT's path is near the one without them. Measured on HRP-2 (whose knee-ankle discs are
# 0.57 rad from the reference, at the ankle's range corners that the ladders' feet visit):
# every map held from the start, the vertical ladder climb failed 'right hand on rung 8'.
MAP_ACTIVATION = 0.4
# [rad] a map whose discs are at least this far from the reference posture is held from the
# start of every call: its rows cost a path that does not come near nothing, and a long step
# into it can no longer end deep inside, where a run that starts cannot get out (HRP-2's hips,
# 0.98 rad away: held on demand, a touch of the inclined ladder's plan ended with the hip's
# meshes 27 mm into each other and then failed; held from the start, that plan is 14 stages)
MAP_FAR = 0.8


@dataclass(frozen=True)
class JointMap:
    """The discs of one joint pair in the plane of the two joint coordinates that move one of
    its links against the other."""

    joints: tuple[int, int]  # the pair's joint ids (sorted)
    coords: tuple[int, int]  # their moving coordinates, indices into qj (the actuated joints)
    discs: np.ndarray  # (n, 3) centre (2,) [rad] and radius [rad] of each disc

    @property
    def digest(self) -> str:
        """A digest of the discs (the rows' constants)."""
        return hashlib.sha1(np.ascontiguousarray(self.discs).tobytes()).hexdigest()[:12]

    def values(self, qj: np.ndarray) -> np.ndarray:
        """(n,) the rows at actuated joint coordinates ``qj`` (nj,): >= 0 outside each disc."""
        d = np.array([qj[self.coords[0]], qj[self.coords[1]]]) - self.discs[:, :2]
        return (d**2).sum(axis=1) / self.discs[:, 2] ** 2 - 1.0

    def gap(self, qj: np.ndarray) -> float:
        """[rad] how far the joints at ``qj`` (nj,) are outside the nearest disc (< 0 inside)."""
        d = np.array([qj[self.coords[0]], qj[self.coords[1]]]) - self.discs[:, :2]
        return float((np.linalg.norm(d, axis=1) - self.discs[:, 2]).min(initial=np.inf))

    def rows(self, qj: ca.SX) -> ca.SX:
        """The rows (n,) as expressions of the actuated joint coordinates ``qj`` (nj,)."""
        u, v = qj[self.coords[0]], qj[self.coords[1]]
        return ca.vertcat(
            *[((u - x) ** 2 + (v - y) ** 2) / r**2 - 1.0 for x, y, r in self.discs.tolist()]
        )


def activation(m: JointMap, q_ref: np.ndarray) -> float:
    """[rad] how near a disc of ``m`` the joints must come for its rows to hold: every posture
    (held from the start) when its discs are MAP_FAR from the reference ``q_ref`` (nq,)."""
    return np.inf if m.gap(q_ref[7:]) >= MAP_FAR else MAP_ACTIVATION


def mapped_pairs(robot: Robot, pm: ProxyModel) -> list[tuple[int, int, tuple[int, int]]]:
    """(a, b, coords) of each candidate pair whose proxies overlap at the reference and whose
    relative placement depends on exactly two joint coordinates ``coords`` (into qj)."""
    model = robot.model
    out = []
    for (a, b), clearance in zip(pm.joint_pairs, pm.clearance, strict=True):
        if clearance >= 0:
            continue
        moving = sorted(set(pm.chains[int(a)]) ^ set(pm.chains[int(b)]))
        joints = [j for j in range(1, model.njoints) if model.joints[j].idx_v - 6 in moving]
        if len(moving) == 2 and all(model.joints[j].nq == 1 for j in joints):
            out.append((int(a), int(b), (moving[0], moving[1])))
    return out


def fit_map(robot: Robot, a: int, b: int, coords: tuple[int, int], q_ref: np.ndarray) -> np.ndarray:
    """(n, 3) the discs of the pair (a, b) in the plane of ``coords``, the other joints at
    ``q_ref`` (which the pair's placement does not depend on)."""
    model, geometry = robot.model, robot.collision_model()
    gdata, data = geometry.createData(), model.createData()
    objs = [
        [i for i, o in enumerate(geometry.geometryObjects) if int(o.parentJoint) == j]
        for j in (a, b)
    ]
    iq = [  # the coordinates' index in q
        model.joints[j].idx_q
        for c in coords
        for j in range(1, model.njoints)
        if model.joints[j].idx_v - 6 == c
    ]
    axes = [
        np.arange(model.lowerPositionLimit[i], model.upperPositionLimit[i] + MAP_STEP, MAP_STEP)
        for i in iq
    ]
    hit = np.zeros((len(axes[0]), len(axes[1])), dtype=bool)
    q = np.array(q_ref, dtype=float)
    for u, x in enumerate(axes[0]):
        for v, y in enumerate(axes[1]):
            q[iq[0]], q[iq[1]] = x, y
            pin.forwardKinematics(model, data, q)
            pin.updateGeometryPlacements(model, data, geometry, gdata)
            hit[u, v] = _meet(geometry, gdata, objs[0], objs[1])
    return _cover(hit, axes)


def _meet(geometry: pin.GeometryModel, gdata: pin.GeometryData, A: list[int], B: list[int]) -> bool:
    """Whether a mesh of ``A`` meets one of ``B`` (placements in ``gdata``)."""
    for i in A:
        for j in B:
            Mi, Mj = gdata.oMg[i], gdata.oMg[j]
            if coal.collide(
                geometry.geometryObjects[i].geometry,
                coal.Transform3s(Mi.rotation, Mi.translation),
                geometry.geometryObjects[j].geometry,
                coal.Transform3s(Mj.rotation, Mj.translation),
                coal.CollisionRequest(),
                coal.CollisionResult(),
            ):
                return True
    return False


def _cover(hit: np.ndarray, axes: list[np.ndarray]) -> np.ndarray:
    """(n, 3) discs covering every cell within MAP_DELTA of a colliding one of ``hit``
    (the grid over ``axes``): the deepest uncovered cell first, its depth in that set plus
    MAP_EXCESS its radius."""
    if not hit.any():
        return np.zeros((0, 3))
    near = ndimage.distance_transform_edt(~hit) * MAP_STEP < MAP_DELTA
    depth = ndimage.distance_transform_edt(near) * MAP_STEP
    U, V = np.meshgrid(axes[0], axes[1], indexing="ij")
    left, discs = near.copy(), []
    while left.any():
        u, v = np.unravel_index(np.argmax(np.where(left, depth, -1.0)), hit.shape)
        radius = depth[u, v] + MAP_EXCESS
        left &= (U - axes[0][u]) ** 2 + (V - axes[1][v]) ** 2 > radius**2
        discs.append((axes[0][u], axes[1][v], radius))
    return np.array(discs)


_MAPS: BoundedCache[tuple[JointMap, ...]] = BoundedCache("joint maps", 16)


def joint_maps(robot: Robot, pm: ProxyModel) -> tuple[JointMap, ...]:
    """The robot's joint maps: fitted once, kept on disk (the package ships the bundled
    robots', ``tools/ship_proxies.py``), in memory per proxy model."""
    key = maps_key(pm)
    return _MAPS.get_or_make(key, lambda: _stored(robot, pm, key))


def maps_key(pm: ProxyModel) -> str:
    """A digest of what the maps depend on: the proxies' key (the robot's files and the
    fitting code), this module's source and constants."""
    h = hashlib.sha1(f"{pm.key}:{MAP_VERSION}:{MAP_STEP}:{MAP_DELTA}:{MAP_EXCESS}".encode())
    h.update(Path(__file__).read_bytes())
    return h.hexdigest()[:16]


def shipped_maps_dir() -> Path:
    """Folder ``data/joint_maps`` of posturegen: the bundled robots' maps (one ``<key>.npz``
    each, :func:`maps_key`), written by ``tools/ship_proxies.py``."""
    return Path(str(importlib.resources.files("posturegen") / "data" / "joint_maps"))


def _stored(robot: Robot, pm: ProxyModel, key: str) -> tuple[JointMap, ...]:
    """The maps from the package or the disk cache, else fitted (and cached)."""
    for path in (shipped_maps_dir() / f"{key}.npz", cache_dir() / f"maps-{key}.npz"):
        if path.is_file():
            try:
                return read_maps(path)
            except (OSError, ValueError, KeyError):
                continue  # a broken file: fit again
    maps = tuple(
        JointMap((a, b), coords, fit_map(robot, a, b, coords, pm.rule.reference_q))
        for a, b, coords in mapped_pairs(robot, pm)
    )
    try:
        write_maps(cache_dir() / f"maps-{key}.npz", maps)
    except OSError:
        pass  # a read-only cache: fit again next time
    return maps


def write_maps(path: Path, maps: tuple[JointMap, ...]) -> Path:
    """Write maps to an ``.npz`` file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {"pairs": np.array([[*m.joints, *m.coords] for m in maps], dtype=int).reshape(-1, 4)}
    for k, m in enumerate(maps):
        arrays[f"discs_{k}"] = m.discs
    np.savez_compressed(path, **arrays)
    return path


def read_maps(path: Path) -> tuple[JointMap, ...]:
    """The maps of an ``.npz`` file written by :func:`write_maps`."""
    with np.load(path, allow_pickle=False) as z:
        return tuple(
            JointMap((int(a), int(b)), (int(i), int(j)), np.array(z[f"discs_{k}"], dtype=float))
            for k, (a, b, i, j) in enumerate(z["pairs"])
        )
