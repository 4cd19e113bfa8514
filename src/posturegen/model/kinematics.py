"""Kinematics and statics of a Pinocchio model as CasADi expressions.

PyPI's Pinocchio has no CasADi bindings, so this module walks the Pinocchio model tree itself:
``oMi = oMparent · jointPlacement · XJ(q)``. Everything here follows Pinocchio's conventions
(free-flyer velocity in the base's local frame, joint order, frames) and is tested against
Pinocchio's own numbers in ``tests/test_kinematics.py``.

The static terms use subtree sums instead of Jacobians: for a revolute joint j with world axis
``a_j`` through ``o_j``, ``g_j(q) = -a_j · Σ_b (c_b - o_j) × m_b g⃗`` and
``(Jᵀf)_j = a_j · Σ_i (p_i - o_j) × f_i`` (bodies b and contact points i beyond joint j).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..errors import ModelError

Expr = ca.SX | ca.MX | ca.DM

_REVOLUTE = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}
_PRISMATIC = {"JointModelPX": 0, "JointModelPY": 1, "JointModelPZ": 2}


_SCRATCH = threading.local()


def scratch_data(model: pin.Model) -> pin.Data:
    """A ``pin.Data`` of ``model`` that this thread's numeric checks reuse (``createData``
    takes 0.3 ms on Talos, three times per collision-avoiding solve); every user runs
    ``forwardKinematics`` before reading it."""
    cache = getattr(_SCRATCH, "data", None)
    if cache is None:  # this thread's own: not registered for clear_caches (other threads')
        cache = _SCRATCH.data = BoundedCache("scratch data", 8, register=False)
    return cache.get_or_make(Ref(model), model.createData)


# a free-flyer's coordinates at the world origin: (x, y, z, qx, qy, qz, qw)
ORIGIN_XYZQUAT = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])


def at_origin(q: np.ndarray) -> np.ndarray:
    """q (nq,) with the free-flyer at the world origin: the placements it gives are in the
    base's frame and depend on the joints q[7:] alone, bit for bit (a self distance computed
    there is the same number wherever the robot stands; from world placements it differs by
    rounding from one base pose to another)."""
    out = np.array(q, dtype=float)
    out[:7] = ORIGIN_XYZQUAT
    return out


def base_to_world(q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (n, 3) [m] in the base's frame to world at q's base pose: R_world_base·p +
    p_world_base."""
    T = pin.XYZQUATToSE3(np.asarray(q[:7], dtype=float))
    return points @ T.rotation.T + T.translation


def skew(v: Expr) -> Expr:
    """[v]× such that skew(v) @ w = v × w."""
    return ca.vertcat(
        ca.horzcat(0, -v[2], v[1]),
        ca.horzcat(v[2], 0, -v[0]),
        ca.horzcat(-v[1], v[0], 0),
    )


def axis_rotation(axis: np.ndarray, angle: Expr) -> Expr:
    """Rodrigues: R = I + sin(a)[k]× + (1 - cos(a))[k]×² for a unit axis k."""
    k = np.asarray(axis, dtype=float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return ca.DM.eye(3) + ca.sin(angle) * ca.DM(K) + (1 - ca.cos(angle)) * ca.DM(K @ K)


def so3_exp(w: Expr, terms: int = 14) -> Expr:
    """exp([w]×) = I + s(θ²)[w]× + c(θ²)[w]×², with the series s = sin θ/θ, c = (1-cos θ)/θ².

    The series are polynomials in θ² = wᵀw, hence smooth at w = 0 (no sqrt), and accurate to
    machine precision for |w| <= π with the default number of terms.
    """
    t2 = ca.dot(w, w)
    # Horner evaluation of both series.
    s = 0
    c = 0
    for k in reversed(range(terms)):
        sign = -1.0 if k % 2 else 1.0
        s = sign / _factorial(2 * k + 1) + t2 * s
        c = sign / _factorial(2 * k + 2) + t2 * c
    W = skew(w)
    return ca.DM.eye(3) + s * W + c * (W @ W)


def _factorial(n: int) -> float:
    out = 1.0
    for i in range(2, n + 1):
        out *= i
    return out


def quat_to_rot(quat_xyzw: Expr) -> Expr:
    """Rotation matrix of a unit quaternion (x, y, z, w), Pinocchio's storage order."""
    x, y, z, w = quat_xyzw[0], quat_xyzw[1], quat_xyzw[2], quat_xyzw[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


@dataclass(frozen=True)
class _JointInfo:
    """Numeric data of one Pinocchio joint, enough to write its placement symbolically."""

    parent: int
    R_parent_joint: np.ndarray  # (3, 3) jointPlacement rotation
    p_parent_joint: np.ndarray  # (3,) jointPlacement translation [m]
    kind: str  # "revolute" | "prismatic" | "freeflyer" | "universe"
    axis: np.ndarray  # (3,) unit axis in the joint frame (unused for the free flyer)
    idx_j: int  # index of this joint's coordinate in the actuated vector qj (-1: free flyer)
    mass: float  # [kg]
    com_local: np.ndarray  # (3,) body COM in the joint frame [m]


@dataclass
class KinematicState:
    """Joint placements oMi (world) of one configuration, as CasADi expressions."""

    R: list[Expr]  # R[i]: (3, 3) rotation of joint i in world
    p: list[Expr]  # p[i]: (3,) position of joint i in world [m]


def _joint_info(model: pin.Model, i: int) -> _JointInfo:
    """Joint i's placement in its parent, kind, unit axis, actuated index and inertia; a
    ModelError for a joint posturegen cannot differentiate."""
    jm = model.joints[i]
    name = jm.shortname()
    M = model.jointPlacements[i]
    inertia = model.inertias[i]
    axis = np.zeros(3)
    if name == "JointModelFreeFlyer":
        if i != 1:
            raise ModelError(f"joint '{model.names[i]}': free flyer below the root")
        kind, idx_j = "freeflyer", -1
    elif name in _REVOLUTE:
        kind, idx_j = "revolute", jm.idx_v - 6
        axis[_REVOLUTE[name]] = 1.0
    elif name in _PRISMATIC:
        kind, idx_j = "prismatic", jm.idx_v - 6
        axis[_PRISMATIC[name]] = 1.0
    elif name == "JointModelRevoluteUnaligned":
        kind, idx_j = "revolute", jm.idx_v - 6
        axis = np.asarray(jm.extract().axis, dtype=float).copy()
    elif name == "JointModelPrismaticUnaligned":
        kind, idx_j = "prismatic", jm.idx_v - 6
        axis = np.asarray(jm.extract().axis, dtype=float).copy()
    else:
        raise ModelError(
            f"joint '{model.names[i]}' has type {name}, which posturegen does not support "
            "(use revolute or prismatic joints with one coordinate)"
        )
    if kind != "freeflyer" and jm.nq != 1:
        raise ModelError(f"joint '{model.names[i]}': expected one coordinate")
    return _JointInfo(
        parent=int(model.parents[i]),
        R_parent_joint=np.array(M.rotation),
        p_parent_joint=np.array(M.translation),
        kind=kind,
        axis=axis / np.linalg.norm(axis) if kind != "freeflyer" else axis,
        idx_j=idx_j,
        mass=float(inertia.mass),
        com_local=np.array(inertia.lever),
    )


class CasadiKinematics:
    """Forward kinematics, frame Jacobians and statics of a free-floating Pinocchio model.

    The model's first joint must be a free flyer; the others revolute or prismatic joints with
    one coordinate (RX/RY/RZ, RevoluteUnaligned, PX/PY/PZ, PrismaticUnaligned).
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        if model.njoints < 2 or model.joints[1].shortname() != "JointModelFreeFlyer":
            raise ModelError("the model's root joint must be a free flyer (load it with one)")
        self.nq = model.nq
        self.nv = model.nv
        self.nj = model.nv - 6  # actuated coordinates
        universe = _JointInfo(
            -1, np.eye(3), np.zeros(3), "universe", np.zeros(3), -1, 0.0, np.zeros(3)
        )
        infos: list[_JointInfo] = [universe]
        infos += [_joint_info(model, i) for i in range(1, model.njoints)]
        self._joints = infos
        self.total_mass = float(sum(j.mass for j in infos))
        # subtree[i]: joints whose body hangs below joint i (i included)
        self.subtree: list[list[int]] = [[] for _ in range(model.njoints)]
        for i in range(1, model.njoints):
            k = i
            while k > 0:
                self.subtree[k].append(i)
                k = int(model.parents[k])
        self.gravity = np.array(model.gravity.linear)  # (3,) [m/s²]

    # ------------------------------------------------------------------ placements
    def forward(self, p_base: Expr, R_base: Expr, qj: Expr) -> KinematicState:
        """Joint placements for base position ``p_base`` (3,), rotation ``R_base`` (3,3), joints
        ``qj`` (nj,)."""
        R: list[Expr] = [ca.DM.eye(3)]
        p: list[Expr] = [ca.DM.zeros(3)]
        for i in range(1, len(self._joints)):
            info = self._joints[i]
            Rp, pp = R[info.parent], p[info.parent]
            Rj = Rp @ info.R_parent_joint
            pj = pp + Rp @ info.p_parent_joint
            if info.kind == "freeflyer":
                Rj, pj = Rj @ R_base, pj + Rp @ (info.R_parent_joint @ p_base)
            elif info.kind == "revolute":
                Rj = Rj @ axis_rotation(info.axis, qj[info.idx_j])
            else:
                pj = pj + Rj @ (info.axis * qj[info.idx_j])
            R.append(Rj)
            p.append(pj)
        return KinematicState(R=R, p=p)

    def forward_q(self, q: Expr) -> KinematicState:
        """Joint placements for a Pinocchio configuration q = (xyz, quaternion xyzw, joints)."""
        return self.forward(q[0:3], quat_to_rot(q[3:7]), q[7:])

    def frame_placement(self, state: KinematicState, frame_id: int) -> tuple[Expr, Expr]:
        """(R_world_frame (3,3), p_world_frame (3,)) of a Pinocchio frame."""
        f = self.model.frames[frame_id]
        i = int(f.parentJoint)
        return state.R[i] @ np.array(f.placement.rotation), state.p[i] + state.R[i] @ np.array(
            f.placement.translation
        )

    def point_world(self, state: KinematicState, joint_id: int, p_local: Expr) -> Expr:
        """World position (3,) of a point given in joint ``joint_id``'s frame."""
        return state.p[joint_id] + state.R[joint_id] @ p_local

    def actuated_joint_ids(self) -> list[int]:
        """Joint ids of the actuated joints, in qj order."""
        ids = [i for i in range(2, len(self._joints))]
        return sorted(ids, key=lambda i: self._joints[i].idx_j)

    # ------------------------------------------------------------------ Jacobians
    def frame_jacobian(self, state: KinematicState, frame_id: int) -> Expr:
        """6×nv Jacobian of a frame in LOCAL_WORLD_ALIGNED (linear rows first), Pinocchio's
        convention: ``[v; ω] = J v_q`` with the base velocity in the base frame."""
        _, p_f = self.frame_placement(state, frame_id)
        joint = int(self.model.frames[frame_id].parentJoint)
        return self.point_jacobian(state, joint, p_f)

    def point_jacobian(self, state: KinematicState, joint_id: int, p_world: Expr) -> Expr:
        """6×nv Jacobian (LOCAL_WORLD_ALIGNED) of a point rigidly attached to joint ``joint_id``."""
        J = ca.SX.zeros(6, self.nv) if isinstance(p_world, ca.SX) else ca.MX.zeros(6, self.nv)
        Rb, pb = state.R[1], state.p[1]
        J[0:3, 0:3] = Rb
        J[0:3, 3:6] = -skew(p_world - pb) @ Rb
        J[3:6, 3:6] = Rb
        self._joint_columns(J, state, joint_id, p_world, 6)
        return J

    def _joint_columns(
        self, J: Expr, state: KinematicState, joint_id: int, p: Expr, offset: int
    ) -> None:
        """Fill the columns offset + idx_j of J (6, ·) with the geometric Jacobian of a point p
        on joint ``joint_id``'s body: revolute ``[a_k × (p - o_k); a_k]``, prismatic
        ``[a_k; 0]``, for its supporting joints k."""
        for k in self.model.supports[joint_id]:
            k = int(k)
            if k < 2:
                continue
            info = self._joints[k]
            a = state.R[k] @ info.axis
            col = offset + info.idx_j
            if info.kind == "revolute":
                J[0:3, col] = ca.cross(a, p - state.p[k])
                J[3:6, col] = a
            else:
                J[0:3, col] = a

    def twist_jacobians(
        self, state: KinematicState, joint_ids: Sequence[int], base_rotation: Expr | None = None
    ) -> dict[int, Expr]:
        """6×nz Jacobians ``[∂p_i/∂z; ω_i]`` of joint frames i w.r.t. coordinates z, rows
        ω_i the frame's angular velocity per unit ż, both in the state's frame. A point
        c = p_i + R_i s then has ∂c/∂z = [I, -[R_i s]×] J_i.

        With ``base_rotation`` (3,), the variable w of R_base = R0·exp([w]×) in ``state``, z is
        (p_base (3,), w (3,), qj (nj,)); without it the state's base is fixed and z = qj. The
        columns of qj are the geometric ones (revolute: ``[a_k × (p_i - o_k); a_k]``); those of
        w have ω = vee(∂R_base/∂w_m · R_baseᵀ), the same for every frame."""
        nb = 6 if base_rotation is not None else 0
        out: dict[int, Expr] = {}
        omega_w = None
        if base_rotation is not None:
            Rb = state.R[1]
            dRb = ca.jacobian(ca.vec(Rb), base_rotation)  # (9, 3)
            cols = []
            for m in range(3):
                S = ca.reshape(dRb[:, m], 3, 3) @ Rb.T
                cols.append(ca.vertcat(S[2, 1], S[0, 2], S[1, 0]))
            omega_w = ca.horzcat(*cols)  # (3, 3)
        for i in joint_ids:
            J = ca.SX(6, nb + self.nj)
            if base_rotation is not None:
                J[0:3, 0:3] = self._joints[1].R_parent_joint
                r = state.p[i] - state.p[1]
                for m in range(3):
                    J[0:3, 3 + m] = ca.cross(omega_w[:, m], r)
                J[3:6, 3:6] = omega_w
            self._joint_columns(J, state, i, state.p[i], nb)
            out[i] = J
        return out

    # ------------------------------------------------------------------ statics
    def com_world(self, state: KinematicState) -> Expr:
        """Center of mass of the whole robot in world (3,) [m]."""
        s = 0
        for i in range(1, len(self._joints)):
            info = self._joints[i]
            s = s + info.mass * self.point_world(state, i, info.com_local)
        return s / self.total_mass

    def static_wrench_terms(
        self,
        state: KinematicState,
        contact_points: Sequence[tuple[int, Expr, Expr]] = (),
    ) -> tuple[Expr, Expr, Expr]:
        """Statics of gravity plus contact forces, in the form needed by the equilibrium.

        ``contact_points``: (joint_id, p_world (3,), f_world (3,)) with f the force on the robot.
        Returns ``(base_force, base_moment, joint_terms)``: the world-frame resultant force [N]
        and moment about the world origin [N·m] of gravity plus all contact forces (both zero at
        equilibrium), and ``joint_terms`` (nj,) = ``g_j(q) - (Jᵀf)_j``, the torque that joint j
        must provide [N·m or N].
        """
        g = self.gravity
        n = len(self._joints)
        # per-body/contact contributions accumulated on their joint, then over subtrees
        mass = [0.0] * n
        first_moment: list[Expr] = [0] * n  # Σ m c (3,)
        force: list[Expr] = [0] * n  # Σ f (3,)
        moment: list[Expr] = [0] * n  # Σ p × f (3,)
        for i in range(1, n):
            info = self._joints[i]
            mass[i] = info.mass
            first_moment[i] = info.mass * self.point_world(state, i, info.com_local)
        for joint_id, p_w, f_w in contact_points:
            force[joint_id] = force[joint_id] + f_w
            moment[joint_id] = moment[joint_id] + ca.cross(p_w, f_w)
        # accumulate children into parents (Pinocchio orders parents before children)
        for i in range(n - 1, 1, -1):
            par = self._joints[i].parent
            mass[par] += mass[i]
            first_moment[par] = first_moment[par] + first_moment[i]
            force[par] = force[par] + force[i]
            moment[par] = moment[par] + moment[i]
        # whole-robot resultant: subtree of the free flyer (joint 1)
        F_total = mass[1] * ca.DM(g) + force[1]
        N_total = ca.cross(first_moment[1], ca.DM(g)) + moment[1]
        joint_terms = [None] * self.nj
        for i in range(2, n):
            info = self._joints[i]
            a = state.R[i] @ info.axis
            o = state.p[i]
            F_sub = mass[i] * ca.DM(g) + force[i]
            if info.kind == "revolute":
                W = ca.cross(first_moment[i], ca.DM(g)) + moment[i] - ca.cross(o, F_sub)
                joint_terms[info.idx_j] = -ca.dot(a, W)
            else:
                joint_terms[info.idx_j] = -ca.dot(a, F_sub)
        return F_total, N_total, ca.vertcat(*joint_terms)

    def generalized_gravity(self, state: KinematicState) -> Expr:
        """g(q) (nv,) in Pinocchio's convention (base rows in the base frame)."""
        F, N, tau_j = self.static_wrench_terms(state)
        Rb, pb = state.R[1], state.p[1]
        # Pinocchio's base rows: -R_bᵀ F and -R_bᵀ (moment about the base origin)
        return ca.vertcat(-Rb.T @ F, -Rb.T @ (N - ca.cross(pb, F)), tau_j)
