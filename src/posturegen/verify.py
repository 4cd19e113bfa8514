"""Independent numeric re-check of a posture with Pinocchio (never with the solver's CasADi).

It reads only the posture's public content (the posture-file dict), so ``posturegen verify
FILE`` and :func:`posturegen.solver.solve.solve` run exactly the same checks:

- q: right size, finite, unit base quaternion, within joint limits;
- torques within effort limits, and the static equilibrium ``[0; τ] + Σ J_iᵀ f_i - g(q) = 0``
  with J_i the Jacobian of each force's application point (its frame's joint);
- contact geometry: each robot patch lies in its surface plane with opposite normals, a fixed
  contact sits at its given pose, a floating one within its yaw range, each force point lies in
  both polygons, each ellipse lies in both polygons;
- friction: each force inside its exact cone |f_t| <= μ f_n (f_n >= 0); with a contact's
  ``grip`` G [N] shared by its k points, |f_t| <= μ (f_n + G/k) (f_n >= -G/k);
- centre of pressure: at least the contact's ``cop_margin`` inside its contact region (of the
  pressures f_n + G/k with a grip);
- tasks: each hard target reached.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ._cache import BoundedCache
from .checks import Check, VerifyReport
from .collision.mesh_check import mesh_collision_checks
from .errors import InputError, PosturegenError
from .io.posture_file import load_posture, model_of_posture
from .model.geometry import ConvexPolygon, Ellipse, intersect
from .model.kinematics import scratch_data
from .terms.contacts import contact_types
from .terms.contacts.base import PlacedContact, points_in_plane
from .terms.tasks import NumericFrames, read_task

# Tolerances of the re-check. Lengths [m], angles [rad], forces relative to the weight.
TOL_JOINT = 1e-6  # [rad] or [m]
TOL_TORQUE = 1e-6  # relative to the effort limit
TOL_EQUILIBRIUM = 1e-6  # relative to the robot's weight [N] (and weight·1 m [N·m])
TOL_GEOMETRY = 1e-6  # [m] and [rad]
TOL_FRICTION = 1e-6  # relative to the robot's weight [N]
TOL_TASK = 1e-6  # [m] and [rad]
# [relative to the weight] a contact bearing less counts its CoP shortfall in proportion to its
# load: the solver meets the CoP rows to 1e-9 of the weight·margin, so the CoP of a contact
# that bears almost nothing is defined only that loosely (and matters as little)
COP_FULL_LOAD = 1e-3


@dataclass
class _Worst:
    """The worst value so far of each contact check (see :func:`_check_contact`)."""

    geometry: float = 0.0  # [m] and [rad]
    inside: float = 0.0  # [m]
    friction: float = 0.0  # relative to the weight
    ellipse_size: float = 0.0  # [m]
    cop: float = 0.0  # [m]

    def checks(self) -> list[Check]:
        return [
            Check("contact geometry", self.geometry, TOL_GEOMETRY),
            Check("contact points inside polygons", max(self.inside, 0.0), TOL_GEOMETRY),
            Check("friction cones", max(self.friction, 0.0), TOL_FRICTION),
            Check("contact ellipse size", max(self.ellipse_size, 0.0), TOL_GEOMETRY),
            Check("centre of pressure margin", max(self.cop, 0.0), TOL_GEOMETRY),
        ]


def verify_posture(
    posture: dict[str, Any], model: pin.Model, geometry: pin.GeometryModel | None = None
) -> VerifyReport:
    """Check a posture dict (posture-file content) against a Pinocchio model; with a
    ``collision`` entry, also on the real collision meshes (``geometry``, loaded from the
    posture's URDF when not given).

    Args:
        posture: a posture file's content (q, torques, contacts with their forces, tasks).
        model: the robot's Pinocchio model.
        geometry: its collision model (default: loaded from the posture's URDF).

    Returns:
        The report: one Check per quantity (joint and torque limits [rad, N·m], contact
        geometry [m], friction and equilibrium [relative to the weight], tasks, meshes [m]),
        ``ok`` when every one is within its tolerance."""
    data = scratch_data(model)
    q = np.asarray(posture["q"], dtype=float)
    if q.shape != (model.nq,) or not np.all(np.isfinite(q)):
        return VerifyReport((Check("q", np.inf, 0.0, f"expected {model.nq} finite numbers"),))
    checks = [Check("base quaternion norm", abs(np.linalg.norm(q[3:7]) - 1.0), 1e-9)]
    checks.append(_joint_limits(model, q))
    tau = np.asarray(posture["torques"], dtype=float)
    if tau.shape != (model.nv - 6,):
        return VerifyReport((*checks, Check("torques", np.inf, 0.0, f"expected {model.nv - 6}")))
    checks.append(_torque_limits(model, tau, float(posture.get("torque_limit_scale", 1.0))))
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    pin.computeJointJacobians(model, data, q)
    gravity = _gravity(posture, model)
    if gravity is None:
        return VerifyReport(
            (*checks, Check("gravity", np.inf, 0.0, "expected 3 finite numbers, not 0"))
        )
    weight = pin.computeTotalMass(model) * float(np.linalg.norm(gravity))
    residual = _gravity_torques(model, data, q, gravity)  # (nv,) becomes the equilibrium's
    residual[6:] += tau
    worst = _Worst()
    for contact in posture.get("contacts", []):
        _check_contact(contact, model, data, weight, residual, worst)
    checks += worst.checks()
    scale = np.full(model.nv, weight)
    checks.append(
        Check("static equilibrium", float(np.abs(residual / scale).max()), TOL_EQUILIBRIUM)
    )
    checks.append(_tasks(posture, model, data, q))
    notes: list[str] = []
    if posture.get("collision") is not None:
        if geometry is None:
            geometry = geometry_of_posture(posture, model)
        mesh_checks, notes = mesh_collision_checks(posture, model, geometry, q)
        checks.extend(mesh_checks)
    return VerifyReport(tuple(checks), tuple(notes))


def _joint_limits(model: pin.Model, q: np.ndarray) -> Check:
    """How far [rad or m] the worst joint is beyond its limits."""
    lo, hi = model.lowerPositionLimit[7:], model.upperPositionLimit[7:]
    excess = np.maximum(lo - q[7:], q[7:] - hi)
    worst = int(np.argmax(excess)) if excess.size else 0
    value = float(max(excess.max(initial=0.0), 0.0))
    return Check("joint limits", value, TOL_JOINT, f"joint {model.names[worst + 2]}")


def _torque_limits(model: pin.Model, tau: np.ndarray, scale: float) -> Check:
    """How far the worst |τ_j| is beyond scale·effort_j, relative to effort_j."""
    effort = np.array(model.effortLimit[6:], dtype=float)
    finite = np.isfinite(effort) & (effort > 0) & (effort < 1e10)
    limit = effort * scale
    over = np.where(finite, (np.abs(tau) - limit) / np.where(finite, effort, 1.0), 0.0)
    return Check("torque limits", float(max(over.max(initial=0.0), 0.0)), TOL_TORQUE)


# the polygons of the surfaces and robot patches that postures name (a posture file's
# vertices; validated and built once each)
_POLYGONS: BoundedCache[ConvexPolygon] = BoundedCache("verified polygons", 256)


def polygon(vertices: Any) -> ConvexPolygon:
    """The convex polygon of a posture file's vertices list [[x, y], ...] [m] (cached on
    their values)."""
    key = tuple(tuple(float(c) for c in v) for v in vertices)
    return _POLYGONS.get_or_make(key, lambda: ConvexPolygon(np.array(key, dtype=float)))


def _frames(contact: dict[str, Any], model: pin.Model, data: pin.Data) -> PlacedContact:
    surf, rp = contact["surface"], contact["robot_patch"]
    T_wc = data.oMf[model.getFrameId(rp["frame"])] * pin.SE3(np.array(rp["placement"], float))
    return PlacedContact(
        pin.SE3(np.array(surf["placement"], dtype=float)),
        polygon(surf["vertices"]),
        T_wc,
        polygon(rp["vertices"]),
    )


def _check_contact(
    contact: dict[str, Any],
    model: pin.Model,
    data: pin.Data,
    weight: float,
    residual: np.ndarray,
    worst: _Worst,
) -> None:
    """One contact's checks into ``worst``; its forces' generalized forces added to
    ``residual`` (nv,)."""
    f = _frames(contact, model, data)
    T_sc = f.T_sc
    # coplanarity with opposite normals (paper eq. 2)
    worst.geometry = max(
        worst.geometry,
        abs(T_sc.translation[2]),
        abs(T_sc.rotation[2, 0]),
        abs(T_sc.rotation[2, 1]),
        abs(T_sc.rotation[2, 2] + 1.0),
    )
    worst.geometry = max(worst.geometry, _pose_error(contact, T_sc))
    _check_forces(contact, f, model, data, weight, residual, worst)
    worst.cop = max(worst.cop, cop_shortfall(contact, f.T_ws, f.P_s, f.T_wc, f.P_c, weight))
    kind = contact_types().get(contact["type"])
    if kind is None:
        worst.inside = np.inf  # a type no registered class re-checks: not verified
    else:
        worst.inside = max(worst.inside, kind.recheck_outside(contact, f))
    ell = contact.get("ellipse")
    if ell is not None:
        worst.inside = max(worst.inside, _ellipse_outside(ell, f.T_ws, f.P_s, f.T_wc, f.P_c))
        worst.ellipse_size = max(worst.ellipse_size, _ellipse_shortfall(ell))


def _pose_error(contact: dict[str, Any], T_sc: pin.SE3) -> float:
    """[m] and [rad]: a fixed contact's distance from its given pose, a floating contact's yaw
    beyond its range (0 for the others)."""
    err = 0.0
    kind = contact_types().get(contact["type"])
    if contact.get("pose") is not None and kind is not None and kind.fixed_in_place:
        pos = np.asarray(contact["pose"]["position"], dtype=float)
        yaw = float(contact["pose"]["yaw"])
        err = max(float(np.abs(T_sc.translation[:2] - pos).max()), abs(_wrap(_yaw(T_sc) - yaw)))
    if contact.get("yaw_range") is not None:  # a floating contact's yaw bounds [rad]
        lo, hi = (float(v) for v in contact["yaw_range"])
        err = max(err, abs(_wrap(_yaw(T_sc) - 0.5 * (lo + hi))) - 0.5 * (hi - lo))
    return err


def _check_forces(
    contact: dict[str, Any],
    f: PlacedContact,
    model: pin.Model,
    data: pin.Data,
    weight: float,
    residual: np.ndarray,
    worst: _Worst,
) -> None:
    """Each force's point on both polygons, its friction cone, and its Jᵀf in ``residual``."""
    forces = contact.get("forces") or []
    if not forces:
        return
    mu = float(contact["mu"])
    n = f.T_ws.rotation[:, 2]
    p_w = np.array([force["point"] for force in forces], dtype=float)  # (k, 3) [m]
    f_w = np.array([force["force"] for force in forces], dtype=float)  # (k, 3) [N]
    # the points must lie on both polygons: in the surface plane and inside both
    p_s = points_in_plane(f.T_ws, p_w)
    p_c = points_in_plane(f.T_wc, p_w)
    worst.geometry = max(worst.geometry, float(np.abs(p_s[:, 2]).max()))
    worst.inside = max(
        worst.inside,
        float(-f.P_s.distance_inside(p_s[:, :2]).min()),
        float(-f.P_c.distance_inside(p_c[:, :2]).min()),
    )
    fn = f_w @ n  # (k,) [N]
    ft = np.linalg.norm(f_w - np.outer(fn, n), axis=1)
    pressed = fn + grip_per_point(contact)  # (k,) [N] the load and the hand's grip
    worst.friction = max(worst.friction, float(np.max(ft - mu * pressed)) / weight)
    worst.friction = max(worst.friction, float(np.max(-pressed)) / weight)
    # generalized forces Σ Jᵀ f at p: J the point's LOCAL_WORLD_ALIGNED Jacobian, per joint
    frames = [x["frame"] for x in forces]
    parent = {name: model.frames[model.getFrameId(name)].parentJoint for name in set(frames)}
    joints = np.array([parent[name] for name in frames])  # (k,)
    for jid in set(parent.values()):
        on = joints == jid
        J = pin.getJointJacobian(model, data, jid, pin.LOCAL_WORLD_ALIGNED)  # (6, nv)
        f_on = f_w[on]  # (k_j, 3) [N]
        residual += J[:3].T @ f_on.sum(axis=0) + J[3:].T @ _moment(
            p_w[on] - data.oMi[jid].translation, f_on
        )


def _moment(r: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Σ_i r_i × f_i (3,) [N·m] of lever arms r (k, 3) [m] and forces f (k, 3) [N]: the
    antisymmetric part of M = rᵀ f (one product, where np.cross costs 10x more on a
    contact's few points)."""
    M = r.T @ f  # (3, 3)
    return np.array([M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0]])


def _ellipse_shortfall(ell: dict[str, Any]) -> float:
    """[m] how far a contact ellipse's radii are short of its minimum radii, or its area of
    its minimum area (divided by the larger radius)."""
    radii = sorted((float(r) for r in ell["radii"]), reverse=True)
    wanted = sorted((float(r) for r in ell.get("min_radii", (0, 0))), reverse=True)
    small = max(wanted[0] - radii[0], wanted[1] - radii[1])
    area_short = float(ell.get("min_area", 0.0)) - np.pi * radii[0] * radii[1]
    return max(small, area_short / max(radii[0], 1e-9))


def _tasks(posture: dict[str, Any], model: pin.Model, data: pin.Data, q: np.ndarray) -> Check:
    """The worst hard task's error beyond its range [m], [rad] or sines (each task's own
    :meth:`posturegen.terms.tasks.Task.violation` on Pinocchio's kinematics of q)."""
    frames = NumericFrames(model, data, q)
    worst, detail = 0.0, ""
    for i, entry in enumerate(posture.get("tasks") or []):
        try:
            task = read_task(entry, f"tasks[{i}]", i)
            if task.weight is not None:
                continue
            violation = task.violation(frames)
        except (PosturegenError, KeyError) as exc:
            return Check("tasks", np.inf, TOL_TASK, f"task {i} cannot be checked: {exc}")
        for block, value in violation.items():
            if not value <= worst:
                worst, detail = value, f"task {i} ({task.kind} {task.subject()}): {block}"
    return Check("tasks", worst, TOL_TASK, detail)


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
        loc = points_in_plane(T, pts)
        out = max(out, float(np.abs(loc[:, 2]).max()), float(-P.distance_inside(loc[:, :2]).min()))
    # an exact margin too (sampled points can miss a tangency): rebuild the ellipse in plane s
    loc_c = points_in_plane(T_ws, c[None])[0]
    u = T_ws.rotation.T @ a1
    v = T_ws.rotation.T @ a2
    r1, r2 = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    if r1 > 0 and r2 > 0:
        e = Ellipse(loc_c[:2], float(np.arctan2(u[1], u[0])), (r1, r2))
        out = max(out, -e.inside_margin(P_s))
    return out


def grip_per_point(contact: dict[str, Any]) -> float:
    """[N] the grip of a hand closed around the surface, per force point: it presses each
    point beyond the load (posturegen.terms.forces); 0 for a contact without grip."""
    forces = contact.get("forces") or []
    grip = float(contact.get("grip") or 0.0)
    return grip / len(forces) if forces else 0.0


def cop_shortfall(
    contact: dict[str, Any],
    T_ws: pin.SE3,
    P_s: ConvexPolygon,
    T_wc: pin.SE3,
    P_c: ConvexPolygon,
    weight: float,
) -> float:
    """How far [m] the centre of pressure CoP = Σ f_n,i·p_i / Σ f_n,i (surface plane) of a
    contact's forces is short of its ``cop_margin`` inside its contact region: its ellipse
    (support), else the intersection of both polygons at the realized pose (fixed). <= 0 when
    it is far enough inside; 0 without a margin or a load; a contact bearing less than
    COP_FULL_LOAD of the weight counts in proportion to its load."""
    margin = float(contact.get("cop_margin") or 0.0)
    forces = contact.get("forces") or []
    if margin <= 0.0 or not forces:
        return 0.0
    points = points_in_plane(T_ws, np.array([f["point"] for f in forces], dtype=float))[:, :2]
    fn = np.array([f["force"] for f in forces], dtype=float) @ T_ws.rotation[:, 2]  # (k,) [N]
    fn = fn + grip_per_point(contact)  # the pressure, with a hand's grip
    total = float(fn.sum())
    if total <= 0.0:
        return 0.0
    cop = fn @ points / total  # (2,)
    ell = contact.get("ellipse")
    if ell is not None:
        centre = points_in_plane(T_ws, np.asarray(ell["center"], dtype=float)[None])[0, :2]
        a1, a2 = ((T_ws.rotation.T @ np.asarray(a, dtype=float))[:2] for a in ell["axes"])
        depth = ellipse_depth(cop, centre, (a1, a2))
    else:
        v_w = np.column_stack([P_c.vertices, np.zeros(P_c.n)]) @ T_wc.rotation.T + T_wc.translation
        patch_s = points_in_plane(T_ws, v_w)[:, :2]  # (n, 2) the patch in the surface plane
        depth = min(float(P_s.distance_inside(cop[None])[0]), _ring_depth(patch_s, cop))
        if depth < TOL_GEOMETRY:  # outside or at the border: the intersection itself (or none)
            region = intersect(ConvexPolygon(patch_s), P_s)
            if region is None:
                return np.inf
            depth = float(region.distance_inside(cop[None])[0])
    return (margin - depth) * min(1.0, total / (COP_FULL_LOAD * weight))


def _ring_depth(ring: np.ndarray, point: np.ndarray) -> float:
    """min_i of the signed distance [m] of ``point`` (2,) to the line of edge i of the convex
    ring (n, 2) (either orientation), > 0 inside. Inside two convex polygons, the smaller of
    both is the distance to the border of their intersection (a ball about the point lies in
    the intersection iff it lies in every half-plane of both)."""
    edge = np.empty_like(ring)  # (n, 2) ring[i+1] - ring[i], cyclically
    edge[:-1] = ring[1:] - ring[:-1]
    edge[-1] = ring[0] - ring[-1]
    turn = np.sign(np.sum(ring[:, 0] * edge[:, 1] - ring[:, 1] * edge[:, 0]))  # +1: ccw
    cross = edge[:, 0] * (point[1] - ring[:, 1]) - edge[:, 1] * (point[0] - ring[:, 0])
    return float(np.min(turn * cross / np.linalg.norm(edge, axis=1)))


def ellipse_depth(
    point: np.ndarray, centre: np.ndarray, axes: tuple[np.ndarray, np.ndarray], samples: int = 4096
) -> float:
    """How far [m] a point (2,) is inside the ellipse centre + a1·cos t + a2·sin t (< 0
    outside): its depth in the polygon of ``samples`` boundary points, a lower bound short
    by at most their chords' sagitta max(|a1|, |a2|)·(2π/samples)²/8 (< 1e-7 m below 0.3 m)."""
    t = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
    a1, a2 = axes
    v = centre + np.outer(np.cos(t), a1) + np.outer(np.sin(t), a2)  # (samples, 2)
    return _ring_depth(v, point)


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
