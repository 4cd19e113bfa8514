"""The mesh checks of a posture (posturegen.verify): coal on the robot's real collision meshes.

- self: every pair of links that the pair rule (posturegen.collision.pairs) leaves checked,
recomputed
  from the robot, minus the pairs the posture file leaves unchecked at the user's request
  (named in a note, each with its depth); the check's value is the deepest intersection [m];
- scene: no mesh more than TOL_PENETRATION inside a box of the scene.
"""

from __future__ import annotations

import collections
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..checks import Check
from ..errors import InputError
from ..model.kinematics import scratch_data
from .pairs import REASONS, joint_pair, pair_rule
from .surface import convex_shape, hull_points, penetration_depth

TOL_PENETRATION = 0.002  # a robot mesh may be at most this far inside a scene box [m]
MIN_DEPTH = 1e-6  # [m] an intersection counts at least this deep (the hulls' EPA may say 0)


# geometry models of the self-collision check (the pairs that pairs.pair_rule leaves
# checked, minus the user's) and their data, per (model, geometry, SRDF, user pairs); the
# model and geometry objects are held (Ref)
_SELF_PAIRS: BoundedCache[tuple[pin.GeometryModel, pin.GeometryData]] = BoundedCache(
    "self-collision check models", 16
)


def _self_pairs_model(
    model: pin.Model,
    geometry: pin.GeometryModel,
    srdf: str | None,
    user: frozenset[tuple[int, int]],
) -> tuple[pin.GeometryModel, pin.GeometryData]:
    """``geometry`` with the collision pairs to check (:meth:`PairRule.checked_geometry_pairs`)
    and a data for it, built once per arguments (each check overwrites its results)."""
    key = (Ref(model), Ref(geometry), srdf, user)
    hit = _SELF_PAIRS.get(key)
    if hit is not None:
        return hit
    gm = geometry.copy()
    gm.removeAllCollisionPairs()
    for i, j in pair_rule(model, geometry, srdf).checked_geometry_pairs(geometry, user):
        gm.addCollisionPair(pin.CollisionPair(i, j))
    return _SELF_PAIRS.put(key, (gm, gm.createData()))


# per geometry model: each object's bounding sphere (centre in its joint's frame, radius) [m]
_BOUNDS: BoundedCache[tuple[np.ndarray, np.ndarray]] = BoundedCache("bounding spheres", 16)


def _bounding_spheres(geometry: pin.GeometryModel) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) centres in the parent joints' frames and (k,) radii of spheres that contain
    each collision object (its vertices' hull: the centroid and the farthest vertex)."""
    hit = _BOUNDS.get(Ref(geometry))
    if hit is not None:
        return hit
    centres, radii = [], []
    for obj in geometry.geometryObjects:
        pts = hull_points(obj)
        c = pts.mean(axis=0)
        centres.append(c)
        radii.append(float(np.linalg.norm(pts - c, axis=1).max()))
    return _BOUNDS.put(Ref(geometry), (np.array(centres).reshape(-1, 3), np.array(radii)))


def user_pairs(posture: dict[str, Any], model: pin.Model) -> frozenset[tuple[int, int]]:
    """The joint pairs that the posture file's ``collision.unchecked`` leaves unchecked at the
    user's request (reason ``user``; every other reason is recomputed from the robot)."""
    out = set()
    for entry in posture["collision"].get("unchecked", []):
        if entry.get("reason") != "user":
            continue
        a, b = (str(n) for n in entry["pair"])
        for n in (a, b):
            if not model.existJointName(n):
                raise InputError(
                    "collision.unchecked",
                    f"the robot has no joint '{n}'",
                    "name joints of the robot's URDF",
                )
        out.add(joint_pair(int(model.getJointId(a)), int(model.getJointId(b))))
    return frozenset(out)


def _pair_depths(
    gm: pin.GeometryModel, gd: pin.GeometryData, pairs: list[tuple[int, int]]
) -> list[tuple[float, str]]:
    """(depth [m], "a/b") of each intersecting pair among ``pairs`` of ``gm`` (placements in
    ``gd``): coal on the meshes decides, the depth is their convex hulls' (EPA: exact for
    convex meshes such as ATLAS's, an upper bound for others), at least MIN_DEPTH."""
    request = coal.CollisionRequest()
    out = []
    for i, j in pairs:
        oi, oj = gm.geometryObjects[i], gm.geometryObjects[j]
        Mi, Mj = gd.oMg[i], gd.oMg[j]
        if coal.collide(
            oi.geometry,
            coal.Transform3s(Mi.rotation, Mi.translation),
            oj.geometry,
            coal.Transform3s(Mj.rotation, Mj.translation),
            request,
            coal.CollisionResult(),
        ):
            depth = penetration_depth(convex_shape(oi), Mi, convex_shape(oj), Mj)
            out.append((max(depth, MIN_DEPTH), f"{oi.name}/{oj.name}"))
    return sorted(out, reverse=True)


# [m] taken off a distance between convex hulls (coal's GJK stops within about 1e-6 m of
# it: 1.07e-6 m above the meshes' own at worst over Talos' objects) so that it stays below
# the meshes' distance
HULL_SLACK = 1e-5


def mesh_clearances(
    model: pin.Model,
    geometry: pin.GeometryModel,
    q: np.ndarray,
    wanted: dict[tuple[int, int], float],
) -> dict[tuple[int, int], float]:
    """[m] for each pair of joints (a, b) of ``wanted``, a lower bound of the distance between
    their meshes at posture q (nq,), at least the pair's wanted clearance [m] exactly when
    the meshes keep it (inf when either joint has no object). Each pair of their objects
    bounds it by the cheapest of: their bounding spheres' gap, their convex hulls' distance
    (coal's GJK, less HULL_SLACK), their meshes' distance (coal on the triangles), taking
    the next only while the last is below the clearance; the meshes' own distance, 0.4 ms
    an object pair (a gripper's ten objects against a thigh: 3.8 ms), is thus measured only
    where the hulls, 20x faster, come closer than the clearance."""
    data = scratch_data(model)
    pin.forwardKinematics(model, data, q)
    joints = {j for pair in wanted for j in pair}
    centres, radii = _bounding_spheres(geometry)
    placed: dict[int, list[tuple[pin.GeometryObject, coal.Transform3s, np.ndarray, float]]] = {}
    for k, obj in enumerate(geometry.geometryObjects):
        if int(obj.parentJoint) not in joints:
            continue
        M = data.oMi[obj.parentJoint] * obj.placement
        centre = data.oMi[obj.parentJoint].act(centres[k])  # (3,) world [m]
        placed.setdefault(int(obj.parentJoint), []).append(
            (obj, coal.Transform3s(M.rotation, M.translation), centre, float(radii[k]))
        )
    out = {}
    for (a, b), clearance in wanted.items():
        out[(a, b)] = min(
            (
                _object_bound(first, second, clearance)
                for first in placed.get(a, [])
                for second in placed.get(b, [])
            ),
            default=np.inf,
        )
    return out


def _object_bound(first: tuple[Any, ...], second: tuple[Any, ...], clearance: float) -> float:
    """[m] a lower bound of two placed objects' distance (object, transform, world centre,
    radius each): their spheres', else their hulls', else their meshes' own, the first that
    reaches ``clearance`` [m] (the meshes' when none does)."""
    oa, Ta, ca, ra = first
    ob, Tb, cb, rb = second
    bound = float(np.linalg.norm(ca - cb)) - ra - rb
    if bound >= clearance:
        return bound
    hulls = coal.distance(
        convex_shape(oa), Ta, convex_shape(ob), Tb, coal.DistanceRequest(), coal.DistanceResult()
    )
    if hulls - HULL_SLACK >= clearance:
        return hulls - HULL_SLACK
    return float(
        coal.distance(
            oa.geometry, Ta, ob.geometry, Tb, coal.DistanceRequest(), coal.DistanceResult()
        )
    )


def _user_note(
    model: pin.Model,
    geometry: pin.GeometryModel,
    data: pin.Data,
    user: frozenset[tuple[int, int]],
) -> str:
    """Names every joint pair left unchecked at the user's request, with how deep its meshes
    intersect (a hand-edited list shows here: nothing is silently skipped)."""
    gdata = geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, gdata)
    parent = [int(o.parentJoint) for o in geometry.geometryObjects]
    parts = []
    for a, b in sorted(user):
        mine = [
            (i, j)
            for i in range(len(parent))
            for j in range(i + 1, len(parent))
            if joint_pair(parent[i], parent[j]) == (a, b)
        ]
        hits = _pair_depths(geometry, gdata, mine)
        state = f"intersecting, {1000 * hits[0][0]:.1f} mm deep" if hits else "apart"
        parts.append(f"{model.names[a]}/{model.names[b]} ({state})")
    return f"{len(user)} NOT checked at the user's request: " + ", ".join(parts)


def self_collision_check(
    posture: dict[str, Any], model: pin.Model, geometry: pin.GeometryModel, data: pin.Data
) -> tuple[Check, str]:
    """The self-collision check on the meshes (``data`` holds the posture's kinematics): the
    deepest intersection [m] among the checked pairs (0 when none), and a note naming the
    pairs left unchecked at the user's request, each with its own depth."""
    srdf = posture["robot"].get("srdf")
    srdf = str(srdf) if srdf else None
    user = user_pairs(posture, model)
    gm, gd = _self_pairs_model(model, geometry, srdf, user)
    pin.updateGeometryPlacements(model, data, gm, gd)
    hits = []
    if pin.computeCollisions(gm, gd, False):  # True when any pair collides
        colliding = [
            (int(cp.first), int(cp.second))
            for cp, res in zip(gm.collisionPairs, gd.collisionResults, strict=True)
            if res.isCollision()
        ]
        hits = _pair_depths(gm, gd, colliding)
    worst = hits[0][0] if hits else 0.0
    detail = ", ".join(f"{name} {1000 * d:.1f} mm" for d, name in hits[:3])
    if len(hits) > 3:
        detail += f" (+{len(hits) - 3} more)"
    check = Check("collision: self (meshes)", worst, 0.0, detail)
    rule = pair_rule(model, geometry, srdf)
    reasons = collections.Counter(rule.unchecked.values())  # (0.26 ms summed reason by reason)
    counts = {r: reasons[r] for r in REASONS[:-1]}
    note = "unchecked pairs: " + ", ".join(f"{n} {r}" for r, n in counts.items())
    if user:
        note += "; " + _user_note(model, geometry, data, user)
    return check, note


def mesh_collision_checks(
    posture: dict[str, Any], model: pin.Model, geometry: pin.GeometryModel, q: np.ndarray
) -> tuple[list[Check], list[str]]:
    """coal on the real meshes: the deepest intersection of a checked self-collision pair
    (:func:`self_collision_check`), and the deepest mesh inside a box, at most
    TOL_PENETRATION (coal tests each mesh against the box shrunk by it; the depth is the
    mesh's convex hull's in the whole box). Returns the checks and notes."""
    col = posture["collision"]
    data = scratch_data(model)
    pin.forwardKinematics(model, data, q)
    out, notes = [], []
    if col.get("self"):
        check, note = self_collision_check(posture, model, geometry, data)
        out.append(check)
        notes.append(note)
    boxes = col.get("boxes", [])
    hits: list[tuple[float, str]] = []
    if boxes:
        gdata = geometry.createData()
        pin.updateGeometryPlacements(model, data, geometry, gdata)
        # broad phase: the objects whose bounding sphere reaches a box
        centres, radii = _bounding_spheres(geometry)
        parents = [int(obj.parentJoint) for obj in geometry.geometryObjects]
        world = np.array(
            [data.oMi[j].act(c) for j, c in zip(parents, centres, strict=True)]
        ).reshape(-1, 3)
        for box in boxes:
            hits += _box_hits(box, model, geometry, gdata, world, radii)
    hits.sort(reverse=True)
    detail = ", ".join(f"{name} {1000 * d:.1f} mm" for d, name in hits[:3])
    out.append(
        Check("collision: scene (meshes)", hits[0][0] if hits else 0.0, TOL_PENETRATION, detail)
    )
    return out, notes


def _box_hits(
    box: dict[str, Any],
    model: pin.Model,
    geometry: pin.GeometryModel,
    gdata: pin.GeometryData,
    world: np.ndarray,
    radii: np.ndarray,
) -> list[tuple[float, str]]:
    """(depth [m], "object/box") of the objects more than TOL_PENETRATION inside a box (the
    joints it allows excepted); ``world`` (k, 3) and ``radii`` (k,) bound the objects."""
    size = np.asarray(box["size"], dtype=float)
    half = size / 2 - TOL_PENETRATION
    if np.any(half <= 0):
        return []  # no mesh can be more than TOL_PENETRATION inside so thin a box
    shape = coal.Box(*(2 * half))
    T_box = pin.SE3(np.asarray(box["placement"], dtype=float))
    allowed = set(box.get("allowed_joints", []))
    local = np.abs((world - T_box.translation) @ T_box.rotation)
    gap = np.linalg.norm(np.maximum(local - half, 0.0), axis=1) - radii  # >0: apart
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    out = []
    for k, obj in enumerate(geometry.geometryObjects):
        if gap[k] > 0 or model.names[int(obj.parentJoint)] in allowed:
            continue
        res.clear()
        M = gdata.oMg[k]
        if coal.collide(
            obj.geometry,
            coal.Transform3s(M.rotation, M.translation),
            shape,
            coal.Transform3s(T_box.rotation, T_box.translation),
            req,
            res,
        ):
            depth = penetration_depth(convex_shape(obj), M, coal.Box(*size), T_box)
            out.append((max(depth, TOL_PENETRATION + MIN_DEPTH), f"{obj.name}/{box['name']}"))
    return out


# per checked-pairs model: its geometry pairs by joint pair (sorted ids)
_BY_JOINTS: BoundedCache[dict[tuple[int, int], list[tuple[int, int]]]] = BoundedCache(
    "geometry pairs by joint pair", 16
)
# per model, pairs and placements: the intersecting pairs of the placed links
_PLACED: BoundedCache[list[tuple[float, str]]] = BoundedCache("placed intersections", 256)


def placed_intersections(
    model: pin.Model,
    geometry: pin.GeometryModel,
    srdf: str | None,
    placed: dict[int, pin.SE3],
    user: frozenset[tuple[int, int]] = frozenset(),
) -> list[tuple[float, str]]:
    """(depth [m], "a/b") of each checked mesh pair between two joints that the contacts
    place (joint id -> its world placement T_world_joint), intersecting there: no posture
    moves one against the other, so such a stance cannot pass the self-collision check.
    Cached on the placements (a planner's stances repeat)."""
    if len(placed) < 2:
        return []
    gm, gd = _self_pairs_model(model, geometry, srdf, user)
    joints = sorted(placed)
    key = (Ref(gm), tuple((j, placed[j].homogeneous.tobytes()) for j in joints))

    def make() -> list[tuple[float, str]]:
        by_joints = _BY_JOINTS.get_or_make(Ref(gm), lambda: _pairs_by_joints(gm))
        pairs = [
            pair
            for i, a in enumerate(joints)
            for b in joints[i + 1 :]
            for pair in by_joints.get((a, b), [])
        ]
        for g in {g for pair in pairs for g in pair}:
            obj = gm.geometryObjects[g]
            gd.oMg[g] = placed[obj.parentJoint] * obj.placement
        return _pair_depths(gm, gd, pairs)

    return _PLACED.get_or_make(key, make)


def _pairs_by_joints(gm: pin.GeometryModel) -> dict[tuple[int, int], list[tuple[int, int]]]:
    """The collision pairs of ``gm`` by the sorted pair of their objects' joints."""
    out: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for cp in gm.collisionPairs:
        a, b = gm.geometryObjects[cp.first], gm.geometryObjects[cp.second]
        key = joint_pair(int(a.parentJoint), int(b.parentJoint))
        out.setdefault(key, []).append((int(cp.first), int(cp.second)))
    return out
