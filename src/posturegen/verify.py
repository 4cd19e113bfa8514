"""Independent numeric re-check of a posture with Pinocchio (never with the solver's CasADi).

It reads only the posture's public content (the posture-file dict), so ``posturegen verify
FILE`` and :func:`posturegen.solve.solve` run exactly the same checks:

- q: right size, finite, unit base quaternion, within joint limits;
- torques within effort limits, and the static equilibrium ``[0; τ] + Σ J_iᵀ f_i - g(q) = 0``
  with J_i the Jacobian of each force's application point (its frame's joint);
- contact geometry: each robot patch lies in its surface plane with opposite normals, a fixed
  contact sits at its given pose, a floating one within its yaw range, each force point lies in
  both polygons, each ellipse lies in both polygons;
- friction: each force inside its exact cone |f_t| <= μ f_n (f_n >= 0);
- tasks: each hard target reached.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .errors import InputError
from .geometry import ConvexPolygon, Ellipse
from .kinematics import scratch_data
from .pairs import REASONS, joint_pair, pair_rule
from .surface import convex_shape, hull_points, penetration_depth

SCHEMA = "posturegen.posture/1"
SEQUENCE_SCHEMA = "posturegen.sequence/1"  # climbs: see posturegen.sequence

# Tolerances of the re-check. Lengths [m], angles [rad], forces relative to the weight.
TOL_JOINT = 1e-6  # [rad] or [m]
TOL_TORQUE = 1e-6  # relative to the effort limit
TOL_EQUILIBRIUM = 1e-6  # relative to the robot's weight [N] (and weight·1 m [N·m])
TOL_GEOMETRY = 1e-6  # [m] and [rad]
TOL_FRICTION = 1e-6  # relative to the robot's weight [N]
TOL_TASK = 1e-6  # [m] and [rad]


@dataclass(frozen=True)
class Check:
    """One verified quantity: its worst value, the tolerance, and whether it passed."""

    name: str
    value: float
    tolerance: float
    detail: str = ""

    @property
    def ok(self) -> bool:
        """value <= tolerance (NaN fails)."""
        return bool(self.value <= self.tolerance)


@dataclass(frozen=True)
class VerifyReport:
    """All checks of one posture."""

    checks: tuple[Check, ...]
    notes: tuple[str, ...] = ()  # what the checks left out, and why

    @property
    def ok(self) -> bool:
        """Every check passed."""
        return all(c.ok for c in self.checks)

    @property
    def failures(self) -> tuple[Check, ...]:
        """The checks that failed."""
        return tuple(c for c in self.checks if not c.ok)

    @property
    def max_violation(self) -> float:
        """Largest value/tolerance ratio times the tolerance unit, i.e. the worst raw value."""
        return max((c.value for c in self.checks), default=0.0)

    def summary(self) -> str:
        """One line per check."""
        return "\n".join(
            f"{'ok  ' if c.ok else 'FAIL'} {c.name}: {c.value:.3g} (tolerance {c.tolerance:.1g})"
            + (f" {c.detail}" if c.detail and not c.ok else "")
            for c in self.checks
        ) + "".join(f"\nnote {n}" for n in self.notes)


def _poly_in_plane(T_world_plane: pin.SE3, points_world: np.ndarray) -> np.ndarray:
    """World points -> (k, 3) coordinates in a plane's frame (z = height above it)."""
    return (points_world - T_world_plane.translation) @ T_world_plane.rotation


def verify_posture(
    posture: dict[str, Any], model: pin.Model, geometry: pin.GeometryModel | None = None
) -> VerifyReport:
    """Check a posture dict (posture-file content) against a Pinocchio model; with a
    ``collision`` entry, also on the real collision meshes (``geometry``, loaded from the
    posture's URDF when not given)."""
    data = scratch_data(model)
    checks: list[Check] = []
    q = np.asarray(posture["q"], dtype=float)
    if q.shape != (model.nq,) or not np.all(np.isfinite(q)):
        return VerifyReport((Check("q", np.inf, 0.0, f"expected {model.nq} finite numbers"),))
    checks.append(Check("base quaternion norm", abs(np.linalg.norm(q[3:7]) - 1.0), 1e-9))
    lo, hi = model.lowerPositionLimit[7:], model.upperPositionLimit[7:]
    excess = np.maximum(lo - q[7:], q[7:] - hi)
    worst = int(np.argmax(excess)) if excess.size else 0
    checks.append(
        Check(
            "joint limits",
            float(max(excess.max(initial=0.0), 0.0)),
            TOL_JOINT,
            f"joint {model.names[worst + 2]}",
        )
    )
    tau = np.asarray(posture["torques"], dtype=float)
    if tau.shape != (model.nv - 6,):
        return VerifyReport((*checks, Check("torques", np.inf, 0.0, f"expected {model.nv - 6}")))
    effort = np.array(model.effortLimit[6:], dtype=float)
    finite = np.isfinite(effort) & (effort > 0) & (effort < 1e10)
    limit = effort * float(posture.get("torque_limit_scale", 1.0))
    over = np.where(finite, (np.abs(tau) - limit) / np.where(finite, effort, 1.0), 0.0)
    checks.append(Check("torque limits", float(max(over.max(initial=0.0), 0.0)), TOL_TORQUE))

    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data, q)
    gravity = _gravity(posture, model)
    if gravity is None:
        return VerifyReport(
            (*checks, Check("gravity", np.inf, 0.0, "expected 3 finite numbers, not 0"))
        )
    weight = pin.computeTotalMass(model) * float(np.linalg.norm(gravity))
    residual = _gravity_torques(model, data, q, gravity)
    residual[6:] += tau
    geo, fric, inside, ellipse_size = 0.0, 0.0, 0.0, 0.0
    for contact in posture.get("contacts", []):
        surf = contact["surface"]
        T_ws = pin.SE3(np.array(surf["placement"], dtype=float))
        P_s = ConvexPolygon(np.array(surf["vertices"], dtype=float))
        rp = contact["robot_patch"]
        fid = model.getFrameId(rp["frame"])
        T_wc = data.oMf[fid] * pin.SE3(np.array(rp["placement"], dtype=float))
        P_c = ConvexPolygon(np.array(rp["vertices"], dtype=float))
        # coplanarity with opposite normals (paper eq. 2)
        T_sc = T_ws.inverse() * T_wc
        geo = max(
            geo,
            abs(T_sc.translation[2]),
            abs(T_sc.rotation[2, 0]),
            abs(T_sc.rotation[2, 1]),
            abs(T_sc.rotation[2, 2] + 1.0),
        )
        if contact.get("pose") is not None and contact["type"] == "fixed":
            pos = np.asarray(contact["pose"]["position"], dtype=float)
            yaw = float(contact["pose"]["yaw"])
            geo = max(
                geo,
                float(np.abs(T_sc.translation[:2] - pos).max()),
                abs(_wrap(_yaw(T_sc) - yaw)),
            )
        if contact.get("yaw_range") is not None:  # a floating contact's yaw bounds [rad]
            lo, hi = (float(v) for v in contact["yaw_range"])
            geo = max(geo, abs(_wrap(_yaw(T_sc) - 0.5 * (lo + hi))) - 0.5 * (hi - lo))
        mu = float(contact["mu"])
        for f in contact.get("forces", []):
            p_w = np.asarray(f["point"], dtype=float)
            f_w = np.asarray(f["force"], dtype=float)
            # the point must lie on both polygons: in the surface plane and inside both
            p_s = _poly_in_plane(T_ws, p_w[None])[0]
            p_c = _poly_in_plane(T_wc, p_w[None])[0]
            geo = max(geo, abs(p_s[2]))
            inside = max(
                inside,
                float(-P_s.distance_inside(p_s[None, :2])[0]),
                float(-P_c.distance_inside(p_c[None, :2])[0]),
            )
            n = T_ws.rotation[:, 2]
            fn = float(n @ f_w)
            ft = float(np.linalg.norm(f_w - fn * n))
            fric = max(fric, (ft - mu * fn) / weight, -fn / weight)
            # generalized force of f at p: Jᵀ f with J the point's LOCAL_WORLD_ALIGNED Jacobian
            fr = model.frames[model.getFrameId(f["frame"])]
            jid = fr.parentJoint
            J = pin.getJointJacobian(model, data, jid, pin.LOCAL_WORLD_ALIGNED)
            lever = p_w - data.oMi[jid].translation
            residual += J[:3].T @ f_w + J[3:].T @ np.cross(lever, f_w)
        if contact["type"] == "inclusive":
            v_c = np.column_stack([P_c.vertices, np.zeros(P_c.n)])
            v_w = v_c @ T_wc.rotation.T + T_wc.translation
            inside = max(
                inside, float(-P_s.distance_inside(_poly_in_plane(T_ws, v_w)[:, :2]).min())
            )
        if contact["type"] == "point":
            p_s = _poly_in_plane(T_ws, np.asarray(contact["point"]["world"], dtype=float)[None])
            inside = max(inside, float(-P_s.distance_inside(p_s[:, :2])[0]))
        ell = contact.get("ellipse")
        if ell is not None:
            inside = max(inside, _ellipse_outside(ell, T_ws, P_s, T_wc, P_c))
            radii = sorted((float(r) for r in ell["radii"]), reverse=True)
            wanted = sorted((float(r) for r in ell.get("min_radii", (0, 0))), reverse=True)
            small = max(wanted[0] - radii[0], wanted[1] - radii[1])
            area_short = float(ell.get("min_area", 0.0)) - np.pi * radii[0] * radii[1]
            ellipse_size = max(ellipse_size, small, area_short / max(radii[0], 1e-9))
    checks.append(Check("contact geometry", geo, TOL_GEOMETRY))
    checks.append(Check("contact points inside polygons", max(inside, 0.0), TOL_GEOMETRY))
    checks.append(Check("friction cones", max(fric, 0.0), TOL_FRICTION))
    checks.append(Check("contact ellipse size", max(ellipse_size, 0.0), TOL_GEOMETRY))
    scale = np.full(model.nv, weight)
    checks.append(
        Check("static equilibrium", float(np.abs(residual / scale).max()), TOL_EQUILIBRIUM)
    )
    task_err = 0.0
    for task in posture.get("tasks", []):
        if task.get("weight") is not None:
            continue
        M = data.oMf[model.getFrameId(task["frame"])]
        task_err = max(task_err, float(np.abs(M.translation - np.asarray(task["target"])).max()))
        if task.get("rotation") is not None:
            err = pin.log3(np.asarray(task["rotation"], dtype=float).T @ M.rotation)
            task_err = max(task_err, float(np.abs(err).max()))
    checks.append(Check("tasks", task_err, TOL_TASK))
    notes: list[str] = []
    if posture.get("collision") is not None:
        if geometry is None:
            geometry = geometry_of_posture(posture, model)
        mesh_checks, notes = mesh_collision_checks(posture, model, geometry, q)
        checks.extend(mesh_checks)
    return VerifyReport(tuple(checks), tuple(notes))


def _gravity(posture: dict[str, Any], model: pin.Model) -> np.ndarray | None:
    """The posture file's ``gravity`` [m/s²] (3,), the model's when the file has none; None
    when it is not 3 finite numbers or is zero (the equilibrium is checked under it)."""
    value = posture.get("gravity")
    if value is None:
        return np.array(model.gravity.linear, dtype=float)
    try:
        g = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    if g.shape != (3,) or not np.all(np.isfinite(g)) or not np.any(g):
        return None
    return g


def _gravity_torques(
    model: pin.Model, data: pin.Data, q: np.ndarray, gravity: np.ndarray
) -> np.ndarray:
    """-g(q) (nv,) for the gravity vector ``gravity`` [m/s²]: the potential is -m·γ·c(q),
    so g(q) = -m J_cᵀ γ with J_c the centre of mass Jacobian."""
    J_com = pin.jacobianCenterOfMass(model, data, q, False)
    return pin.computeTotalMass(model) * (J_com.T @ gravity)


TOL_PENETRATION = 0.002  # a robot mesh may be at most this far inside a scene box [m]
MIN_DEPTH = 1e-6  # [m] an intersection counts at least this deep (the hulls' EPA may say 0)


# geometry models of the self-collision check (the pairs that pairs.pair_rule leaves
# checked, minus the user's) and their data, per (model, geometry, SRDF, user pairs); the
# model and geometry objects are held so that their ids stay theirs
_SELF_PAIRS: dict[
    tuple[Any, ...], tuple[pin.Model, pin.GeometryModel, pin.GeometryModel, pin.GeometryData]
] = {}


def _self_pairs_model(
    model: pin.Model,
    geometry: pin.GeometryModel,
    srdf: str | None,
    user: frozenset[tuple[int, int]],
) -> tuple[pin.GeometryModel, pin.GeometryData]:
    """``geometry`` with the collision pairs to check (:meth:`PairRule.checked_geometry_pairs`)
    and a data for it, built once per arguments (each check overwrites its results)."""
    key = (id(model), id(geometry), srdf, user)
    hit = _SELF_PAIRS.get(key)
    if hit is not None and hit[0] is model and hit[1] is geometry:
        return hit[2], hit[3]
    gm = geometry.copy()
    gm.removeAllCollisionPairs()
    for i, j in pair_rule(model, geometry, srdf).checked_geometry_pairs(geometry, user):
        gm.addCollisionPair(pin.CollisionPair(i, j))
    if len(_SELF_PAIRS) >= 16:
        _SELF_PAIRS.clear()
    gd = gm.createData()
    _SELF_PAIRS[key] = (model, geometry, gm, gd)
    return gm, gd


# per geometry model: each object's bounding sphere (centre in its joint's frame, radius) [m]
_BOUNDS: dict[int, tuple[pin.GeometryModel, np.ndarray, np.ndarray]] = {}


def _bounding_spheres(geometry: pin.GeometryModel) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) centres in the parent joints' frames and (k,) radii of spheres that contain
    each collision object (its vertices' hull: the centroid and the farthest vertex)."""
    hit = _BOUNDS.get(id(geometry))
    if hit is not None and hit[0] is geometry:
        return hit[1], hit[2]
    centres, radii = [], []
    for obj in geometry.geometryObjects:
        pts = hull_points(obj)
        c = pts.mean(axis=0)
        centres.append(c)
        radii.append(float(np.linalg.norm(pts - c, axis=1).max()))
    if len(_BOUNDS) >= 16:
        _BOUNDS.clear()
    _BOUNDS[id(geometry)] = (geometry, np.array(centres).reshape(-1, 3), np.array(radii))
    return _BOUNDS[id(geometry)][1], _BOUNDS[id(geometry)][2]


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
    counts = {r: sum(v == r for v in rule.unchecked.values()) for r in REASONS[:-1]}
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


def geometry_of_posture(posture: dict[str, Any], model: pin.Model) -> pin.GeometryModel:
    """The collision meshes of the posture's URDF (package_dirs from the posture)."""
    robot = posture["robot"]
    try:
        return pin.buildGeomFromUrdf(
            model,
            str(robot["urdf"]),
            pin.GeometryType.COLLISION,
            package_dirs=[str(p) for p in robot.get("package_dirs", [])],
        )
    except ValueError as exc:
        raise InputError(
            "robot.package_dirs",
            f"cannot load the collision meshes: {exc}",
            "give the folders that hold the URDF's meshes",
        ) from exc


def _wrap(angle: float) -> float:
    """The angle in (-π, π] [rad]."""
    return float(np.arctan2(np.sin(angle), np.cos(angle)))


def _yaw(T_sc: pin.SE3) -> float:
    """ψ of T_sc = Trans·Rz(ψ)·Rx(π): the angle of the patch x axis in the surface plane."""
    return float(np.arctan2(T_sc.rotation[1, 0], T_sc.rotation[0, 0]))


def _ellipse_outside(
    ell: dict[str, Any], T_ws: pin.SE3, P_s: ConvexPolygon, T_wc: pin.SE3, P_c: ConvexPolygon
) -> float:
    """How far [m] the contact ellipse sticks out of either polygon (<= 0: inside both)."""
    c = np.asarray(ell["center"], dtype=float)
    a1, a2 = (np.asarray(a, dtype=float) for a in ell["axes"])
    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    pts = c + np.outer(np.cos(t), a1) + np.outer(np.sin(t), a2)  # (256, 3) world
    out = 0.0
    for T, P in ((T_ws, P_s), (T_wc, P_c)):
        loc = _poly_in_plane(T, pts)
        out = max(out, float(np.abs(loc[:, 2]).max()), float(-P.distance_inside(loc[:, :2]).min()))
    # an exact margin too (sampled points can miss a tangency): rebuild the ellipse in plane s
    loc_c = _poly_in_plane(T_ws, c[None])[0]
    u = T_ws.rotation.T @ a1
    v = T_ws.rotation.T @ a2
    r1, r2 = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    if r1 > 0 and r2 > 0:
        e = Ellipse(loc_c[:2], float(np.arctan2(u[1], u[0])), (r1, r2))
        out = max(out, -e.inside_margin(P_s))
    return out


def read_json(path: str | Path, missing_fix: str, invalid_fix: str) -> Any:
    """The parsed JSON of a file, or an InputError naming the file (``missing_fix`` when it
    does not exist, ``invalid_fix`` when it is not JSON)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise InputError(str(path), "no such file", missing_fix) from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(str(path), "cannot read it", "check the path") from exc
    except json.JSONDecodeError as exc:
        raise InputError(str(path), f"invalid JSON at line {exc.lineno}", invalid_fix) from exc


def load_posture(path: str | Path) -> dict[str, Any]:
    """Read a posture file and check its schema and required fields."""
    path = Path(path)
    data = read_json(path, "give the path of a posture.json", "give a posture file")
    if not isinstance(data, dict) or data.get("schema") != SCHEMA:
        raise InputError(
            f"{path}: schema", f'expected "{SCHEMA}"', "give a file written by posturegen solve"
        )
    for key in ("robot", "q", "torques", "contacts"):
        if key not in data:
            raise InputError(f"{path}: {key}", "missing", "give a file written by posturegen solve")
    return data


def model_of_posture(posture: dict[str, Any]) -> pin.Model:
    """The Pinocchio model named by a posture's ``robot`` entry (URDF + free flyer)."""
    urdf = Path(str(posture["robot"].get("urdf", "")))
    if not urdf.is_file():
        raise InputError("robot.urdf", f"no file {urdf}", "regenerate the posture on this machine")
    return pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())


def verify_file(path: str | Path) -> VerifyReport:
    """Re-check a posture file (``posturegen verify``)."""
    posture = load_posture(path)
    model = model_of_posture(posture)
    try:
        return verify_posture(posture, model)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(
            str(path),
            f"malformed posture file ({exc.__class__.__name__}: {exc})",
            "give a file written by posturegen solve",
        ) from exc
