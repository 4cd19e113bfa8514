"""Collision avoidance (paper eq. 1, rows 3-4) with smooth conservative sphere proxies.

Proxies (:mod:`posturegen.collision.proxies`, fitted by :mod:`posturegen.collision.proxy_fit`):
each joint's
collision geometry is covered by spheres that contain its whole surface and stand at most
1 cm outside it; the candidate self pairs are every pair of links that the pair rule
(:mod:`posturegen.collision.pairs`) leaves checked, each held at least min(margin, its clearance at
the
reference posture) apart.

Distances, as smooth CasADi expressions:

- sphere-sphere: ``|c_a - c_b| - r_a - r_b`` (smooth wherever the centres differ);
- sphere-box: the six face distances ``s_k = n_k·c - h_k`` of the box give a conservative
  distance ``max_k s_k <= dist(c, box)``; its smooth lower bound
  ``LSE_β(s) - log(6)/β <= max_k s_k`` (log-sum-exp, β = 300 /m, so at most 6 mm
  conservative) minus the radius is the distance d, and the row is d saturated at
  margin + ENV_SATURATION by a smooth minimum (still d >= margin; constant far from the box).
  Hence capsule-box and mesh-box care are avoided.

Self rows are one per pair of limbs (the kinematic chains between branchings): a smooth
minimum (-LSE, SOFT_MIN_BETA) of their sphere pairs' distances minus each pair's clearance,
computed in the base frame.

The rows bring their own exact Jacobian and Hessian (:func:`_soft_min_rows`, through the
links' twist Jacobians; tested equal to CasADi's): CasADi's automatic Hessian redoes each sphere
pair's work once per colour of its columns, and was two thirds of Talos' Hessian of the
Lagrangian with 150 self pairs.

Rows are kept few by an active set: of the pairs closer than ``activation`` beyond their
clearance (self pairs; ``environment_activation`` beyond the margin for sphere-box pairs) at
the current posture, the closest few of each pair of links enter the program
(:mod:`posturegen.collision.active_set`);
after a solve every candidate pair is checked and the violated ones are added (as many per
pair of links) before solving again (:func:`posturegen.solver.solve.solve`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..model.kinematics import skew
from ..model.robot import Robot
from ..terms.nlp import BlockDerivatives, BuildContext, Instance, Term
from .boxes import BETA, EnvBox
from .proxies import SLIDE, ProxyModel, closest, proxy_model
from .proxy_fit import Sphere

__all__ = ["ProxyModel", "Sphere", "proxy_model"]


# --------------------------------------------------------------------------- distances (numpy)
# --------------------------------------------------------------------------- the first start
SEPARATION = 0.03  # [m] how far above its clearance the first start puts each close pair
SEPARATED_PER_LINK = 2  # the closest sphere pairs of each joint pair that the start parts
# steps of the start, each at most this far on any joint [rad]: a full step moved Talos' left
# shoulder far enough to put its wrist 3 cm into its thigh, unseen until the next step
SEPARATION_STEPS = 6
SEPARATION_STEP = 0.1


def _free_joints(model: pin.Model, contact_joints: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and configuration indices of the one-coordinate joints that are not on a
    chain from the base to a contact joint."""
    support: set[int] = set()
    for j in contact_joints:
        while j > 0:
            support.add(j)
            j = int(model.parents[j])
    free = [j for j in range(2, model.njoints) if j not in support and model.joints[j].nq == 1]
    movable = np.array([model.joints[j].idx_v for j in free], dtype=int)
    return movable, np.array([model.joints[j].idx_q for j in free], dtype=int)


def separated_start(
    robot: Robot,
    pm: ProxyModel,
    links: np.ndarray,
    margin: float,
    q: np.ndarray,
    contact_joints: list[int],
) -> np.ndarray:
    """Joints (nj,) of q moved so that the candidate joint pairs ``links`` (indices into
    ``pm.joint_pairs``) closer than the margin + SEPARATION are about that far apart (those
    closer than the margin at the reference posture: no closer than there):
    SEPARATION_STEPS damped least-norm steps Δq = Aᵀ(AAᵀ + 1e-4·I)⁻¹ b (scaled down to
    SEPARATION_STEP) over the joints that carry no contact (the chains from the base to
    ``contact_joints`` stay), A the distance gradients n·(J_a - J_b) of each joint pair's
    SEPARATED_PER_LINK closest sphere pairs, b their shortfalls; clipped to the joint limits.

    IPOPT starts there instead of at q (the posture cost still pulls towards q). In
    half-sitting Talos' forearms are 4 mm above the 1 cm margin from its thighs, and the first
    steps towards a target near the body were cut to a few percent by those rows:
    talos-near-body-collision took 26.5 and 24.5 median iterations (two seeds), 25.0 and 23.5
    from the separated start, 22.5 and 21.0 with it and COLLISION_MU_INIT = 1e-3."""
    key = (
        Ref(robot.model),
        np.asarray(q, dtype=float).tobytes(),
        margin,
        tuple(contact_joints),
        hashlib.sha1(np.asarray(links).tobytes()).digest(),
    )
    hit = _SEPARATED.get(key)
    if hit is not None:
        return hit.copy()
    model = robot.model
    data = model.createData()
    movable, movable_q = _free_joints(model, contact_joints)
    q = np.array(q, dtype=float)
    if movable.size == 0 or len(links) == 0:
        return q[7:]  # nothing to part: not worth a cache entry
    held = pm.pair_clearance(margin)  # (P,) pairs tighter at the reference are left there
    target = np.where(pm.clearance < margin, held, held + SEPARATION)
    for _ in range(SEPARATION_STEPS):
        pin.forwardKinematics(model, data, q)
        centers = pm.centers_world(model, data)
        near = closest(pm.close_pairs(centers, target, links), SEPARATED_PER_LINK)
        if len(near.d) == 0:
            break
        pin.computeJointJacobians(model, data, q)
        rows, short = [], []
        for i, j, link, dk in zip(near.i, near.j, near.link, near.d, strict=True):
            grad = _pair_gradient(model, data, pm, centers, (int(i), int(j)))
            if np.linalg.norm(grad[movable]) > 1e-6:  # pairs the free joints can part
                rows.append(grad[movable])
                short.append(target[link] - dk)
        if not rows:
            break
        A, b = np.array(rows), np.array(short)
        step = A.T @ np.linalg.solve(A @ A.T + 1e-4 * np.eye(len(b)), b)
        q[movable_q] += step * min(1.0, SEPARATION_STEP / max(np.abs(step).max(), 1e-12))
        q[7:] = np.clip(q[7:], robot.q_lower, robot.q_upper)
    _SEPARATED.put(key, q[7:].copy())
    return q[7:]


def _pair_gradient(
    model: pin.Model,
    data: pin.Data,
    pm: ProxyModel,
    centers: np.ndarray,
    pair: tuple[int, int],
) -> np.ndarray:
    """(nv,) the gradient of |c_i - c_j| - r_i - r_j: n·(J_i - J_j), n the unit vector from
    c_j to c_i, J the sphere centres' Jacobians (joint Jacobians already in ``data``)."""
    i, j = pair
    n = centers[i] - centers[j]
    n /= max(float(np.linalg.norm(n)), 1e-12)
    grad = np.zeros(model.nv)
    for s, sign in ((i, 1.0), (j, -1.0)):
        jid = pm.spheres[s].joint_id
        J = pin.getJointJacobian(model, data, jid, pin.LOCAL_WORLD_ALIGNED)
        lever = centers[s] - data.oMi[jid].translation
        grad += sign * (n @ (J[:3] - pin.skew(lever) @ J[3:]))
    return grad


# separated starts per (model, q, margin, contacts, links): a planner's queries share them
_SEPARATED: BoundedCache[np.ndarray] = BoundedCache("separated starts", 64)


# --------------------------------------------------------------------------- the program's rows
# [1/m] sharpness of the smooth minimum over a link pair's sphere pairs: conservative by at most
# log(n)/β (n sphere pairs, 1.5 cm for 20), by much less when one pair is the closest by a few
# mm. 200 /m: talos-near-body-collision took 26.5 median iterations, 500 /m 28.5, 1000 /m 32.5.
SOFT_MIN_BETA = 1000.0
# [m] a sphere-box row is saturated at margin + this: -LSE(-d, -(margin + s)) >= margin, which
# still implies d >= margin (a smooth minimum is below each of its arguments) and is constant
# once the sphere is a few cm away. IPOPT writes an inequality row as g(x) - s = 0 with a slack
# s >= 0, so a far row's nonlinearity along a long step counted as infeasibility and cut steps
# that the row had no reason to stop: talos-box-collision took 29.5 median iterations
# unsaturated, 19 at 5 cm (18 at 5 and 10 cm on another seed, 22.5 at 3 cm). Self rows are
# left unsaturated: the far ones' barrier keeps the arm off the body on its way, and saturated
# at 5 or 10 cm talos-near-body-collision took 1-2 more median iterations.
ENV_SATURATION = 0.05


def _held(margin: Any, clearance: float) -> Any:
    """How far apart a pair is held (ProxyModel.pair_clearance): min(margin, clearance), or
    clearance - SLIDE when its proxies overlap at the reference posture."""
    return clearance - SLIDE if clearance < 0 else ca.fmin(margin, clearance)


def _center(state: Any, sphere: Sphere) -> Any:
    """Symbolic centre (3,) of a proxy sphere in the frame of a kinematic state."""
    return state.p[sphere.joint_id] + state.R[sphere.joint_id] @ sphere.center


@dataclass
class _Element:
    """One argument v of a row's smooth minimum, a function of a few sphere centres c_i:
    ``grads[i]`` = ∂v/∂c_i (3,), ``curvature[(i, j)]`` (i <= j) the (3, 3) block of
    ∇²v - β∇v∇vᵀ (β = SOFT_MIN_BETA); a constant has neither."""

    value: Any
    grads: dict[int, Any] = field(default_factory=dict)
    curvature: dict[tuple[int, int], Any] = field(default_factory=dict)


def _pair_element(c: dict[int, Any], r: np.ndarray, i: int, j: int, clearance: Any) -> _Element:
    """v = |c_i - c_j| - r_i - r_j - m (m the pair's clearance, a parameter): ∇v = (n, -n),
    ∇²_u v = (I - nnᵀ)/|u| for u = c_i - c_j."""
    u = c[i] - c[j]
    length = ca.sqrt(ca.dot(u, u) + 1e-12)
    n = u / length
    K = (ca.SX.eye(3) - n @ n.T) / length - SOFT_MIN_BETA * (n @ n.T)
    value = length - r[i] - r[j] - clearance
    return _Element(value, {i: n, j: -n}, {(i, i): K, (j, j): K, (i, j): -K})


def _box_element(c: Any, i: int, box: Any, radius: float) -> _Element:
    """v = LSE_β(s) - log(6)/β - r over the six face distances s = (l - h, -l - h) of the
    box-frame centre l = R_bᵀ(c - p_b) (see the module doc). With σ = softmax(βs) and
    a = σ⁺ - σ⁻ (3,), ∇_l v = a and ∇²_l v = β(diag(σ⁺ + σ⁻) - aaᵀ); in the world,
    ∇v = R_b a and ∇²v = R_b ∇²_l v R_bᵀ."""
    Rb, pb, h = ca.reshape(box[0:9], 3, 3), box[9:12], box[12:15]
    local = Rb.T @ (c - pb)
    s = ca.vertcat(local - h, -local - h)  # six face distances
    smax = ca.mmax(s)
    ex = ca.exp(BETA * (s - smax))
    total = ca.sum1(ex)
    v = smax + ca.log(total) / BETA - np.log(6.0) / BETA - radius
    plus, minus = ex[0:3] / total, ex[3:6] / total
    a = plus - minus
    grad = Rb @ a
    hess = Rb @ (BETA * (ca.diag(plus + minus) - a @ a.T)) @ Rb.T
    return _Element(v, {i: grad}, {(i, i): hess - SOFT_MIN_BETA * (grad @ grad.T)})


class _TwistSum:
    """Σ A_iᵀ X A_j (6, 6) over the sphere pairs of a pair of links, A = [I, -[ρ]×] the map
    from a link twist to the velocity of its point p + ρ: the four 3×3 blocks summed, the
    6×6 made once (per sphere pair it took a third of the build of Talos' rows)."""

    def __init__(self) -> None:
        self.blocks: list[Any] = [0, 0, 0, 0]  # X, -X[ρ_j], [ρ_i]X, -[ρ_i]X[ρ_j]
        self.mirrored: list[Any] = [0, 0, 0, 0]  # the same, to add transposed

    def add(self, X: Any, skew_i: Any, skew_j: Any, twice: bool = False) -> None:
        """Add A_iᵀ X A_j (and its transpose when ``twice``: i and j of one link)."""
        Y = -X @ skew_j
        target = self.mirrored if twice else self.blocks
        for k, v in enumerate((X, Y, skew_i @ X, skew_i @ Y)):
            target[k] = target[k] + v

    def matrix(self) -> Any:
        """The 6×6 sum."""
        out = _stack(self.blocks)
        if any(not isinstance(b, int) for b in self.mirrored):
            m = _stack(self.mirrored)
            out = out + m + m.T
        return out


def _stack(blocks: list[Any]) -> Any:
    """[[B0, B1], [B2, B3]] (6, 6) from four 3×3 blocks (0 for an empty one)."""
    b = [ca.SX.zeros(3, 3) if isinstance(v, int) else v for v in blocks]
    return ca.vertcat(ca.horzcat(b[0], b[1]), ca.horzcat(b[2], b[3]))


def _soft_min_rows(
    ctx: BuildContext,
    state: Any,
    spheres: list[Sphere],
    rows: list[list[_Element]],
    margin: Any,
    base_rotation: Any,
) -> tuple[Any, Callable[[], BlockDerivatives]]:
    """Rows softmin_β(v_e) - margin over elements of sphere centres in ``state``, and their
    derivatives w.r.t. z (``CasadiKinematics.twist_jacobians``: z = qj for a state of fixed
    base, else (p_base, w, qj)).

    With weights w_e = softmax(-βv)_e and ḡ = Σ w_e ∇v_e, ∇row = ḡ and
    ∇²row = Σ w_e (∇²v_e - β∇v_e∇v_eᵀ) + βḡḡᵀ. Through the centres c_i = p_L + R_L s_i:
    ∂c_i/∂z = A_i J_L, so ∇²_z(λᵀrows) = Σ J_Lᵀ (A_iᵀ K A_j) J_L' (the curvature blocks
    summed per pair of links first), the rank-one terms βλḡḡᵀ (in z, or per centre for rows
    of one centre), and Σ_L ∇²_z(F_L·p_L + <G_L, R_L>) with the first-order weights
    f_i = Σ λ ∂row/∂c_i, F_L = Σ f_i, G_L = Σ f_i s_iᵀ held fixed. CasADi's own Hessian
    repeats each sphere pair's work once per colour of the Hessian's columns; this one does
    it once (Talos, 153 pairs: 74k instead of 117k instructions, tests/test_collision.py
    checks both equal). The derivatives are built when the returned function is called, that
    is only when a solver is built from the expressions: a structure whose library is in the
    disk cache does not pay for them."""
    values, soft = _soft_min_values(rows, margin)
    z = (
        ctx.joints
        if base_rotation is None
        else ca.vertcat(ctx.base_position, base_rotation, ctx.joints)
    )

    def build() -> BlockDerivatives:
        return _soft_min_derivatives(ctx, state, spheres, rows, soft, z, base_rotation)

    return ca.vertcat(*values), build


def _soft_min_values(rows: list[list[_Element]], margin: Any) -> tuple[list[Any], list[Any]]:
    """Each row's softmin_β(v_e) - margin, and soft[k]: (exp(-β(v - min v)), its sum) of row
    k's smooth minimum (None for a row of one element)."""
    values, soft = [], []
    for elements in rows:
        v = ca.vertcat(*[e.value for e in elements])
        if len(elements) == 1:
            values.append(v - margin)
            soft.append(None)
        else:
            m = ca.mmin(v)
            ex = ca.exp(-SOFT_MIN_BETA * (v - m))
            total = ca.sum1(ex)
            values.append(m - ca.log(total) / SOFT_MIN_BETA - margin)
            soft.append((ex, total))
    return values, soft


@dataclass
class _Sums:
    """What the rows' derivatives accumulate (see :func:`_soft_min_rows`)."""

    diag: dict[int, Any]  # Σ λ w K_ii per centre
    cross: dict[tuple[int, int], Any]  # Σ λ w K_ij per pair of centres
    first: dict[int, Any]  # f_i = Σ λ ∂row/∂c_i
    jac_rows: list[Any]
    rank_one: Any  # Σ βλḡḡᵀ in z


def _soft_min_derivatives(
    ctx: BuildContext,
    state: Any,
    spheres: list[Sphere],
    rows: list[list[_Element]],
    soft: list[Any],
    z: Any,
    base_rotation: Any,
) -> BlockDerivatives:
    """The rows' Jacobian and the Hessian of λᵀrows in z (see :func:`_soft_min_rows`)."""
    lam = ca.SX.sym("lam", len(rows))
    link_of = {i: spheres[i].joint_id for row in rows for e in row for i in e.grads}
    J = ctx.kin.twist_jacobians(state, sorted(set(link_of.values())), base_rotation)
    rho = {i: state.R[L] @ spheres[i].center for i, L in link_of.items()}
    nz = next(iter(J.values())).shape[1] if J else 0
    sums = _Sums(
        {i: ca.SX.zeros(3, 3) for i in link_of},
        {},
        {i: ca.SX.zeros(3) for i in link_of},
        [],
        ca.SX(nz, nz),
    )
    for k, elements in enumerate(rows):
        _add_row(sums, k, elements, soft[k], lam, link_of, rho, J, nz)
    H = _curvature_hessian(sums, link_of, rho, J)
    Hk = _kinematic_hessian(sums.first, link_of, spheres, state, J, z)
    if Hk is not None:
        H = H + Hk
    jac = ca.vertcat(*sums.jac_rows) if sums.jac_rows else ca.SX(0, nz)
    return BlockDerivatives(z=z, jacobian=jac, lam=lam, hessian=H)


def _add_row(
    sums: _Sums,
    k: int,
    elements: list[_Element],
    soft_k: Any,
    lam: Any,
    link_of: dict[int, int],
    rho: dict[int, Any],
    J: dict[int, Any],
    nz: int,
) -> None:
    """Row k's gradient (a Jacobian row), curvature blocks, first-order weights and rank-one
    term, added to ``sums``."""
    if soft_k is None:
        weights: Any = [1.0]
    else:
        ex, total = soft_k
        weights = [ex[n] / total for n in range(len(elements))]
    gbar: dict[int, Any] = {}
    for e, w in zip(elements, weights, strict=True):
        for i, g in e.grads.items():
            gbar[i] = gbar.get(i, 0) + w * g
        for (i, j), K in e.curvature.items():
            if i == j:
                sums.diag[i] = sums.diag[i] + lam[k] * w * K
            else:
                sums.cross[(i, j)] = sums.cross.get((i, j), 0) + lam[k] * w * K
    wrench: dict[int, Any] = {}
    for i, g in gbar.items():
        sums.first[i] = sums.first[i] + lam[k] * g
        L = link_of[i]
        wrench[L] = wrench.get(L, 0) + ca.vertcat(g, ca.cross(rho[i], g))
    grad = ca.SX(nz, 1)
    for L, W in wrench.items():
        grad = grad + J[L].T @ W
    sums.jac_rows.append(grad.T)
    if len(gbar) == 1:
        ((i, g),) = gbar.items()
        sums.diag[i] = sums.diag[i] + lam[k] * SOFT_MIN_BETA * (g @ g.T)
    elif gbar:
        sums.rank_one = sums.rank_one + lam[k] * SOFT_MIN_BETA * (grad @ grad.T)


def _curvature_hessian(
    sums: _Sums, link_of: dict[int, int], rho: dict[int, Any], J: dict[int, Any]
) -> Any:
    """The rank-one terms and Σ J_Lᵀ (A_iᵀ K A_j) J_L' over the curvature blocks, summed per
    pair of links first."""
    sk = {i: skew(r) for i, r in rho.items()}  # [ρ_i]×, once per sphere
    blocks: dict[tuple[int, int], _TwistSum] = {}
    for i, D in sums.diag.items():
        L = link_of[i]
        blocks.setdefault((L, L), _TwistSum()).add(D, sk[i], sk[i])
    for (i, j), X in sums.cross.items():
        a, b = (i, j) if link_of[i] <= link_of[j] else (j, i)
        X = X if a == i else X.T
        key = (link_of[a], link_of[b])
        blocks.setdefault(key, _TwistSum()).add(X, sk[a], sk[b], twice=key[0] == key[1])
    H = sums.rank_one
    for (La, Lb), M in blocks.items():
        part = J[La].T @ M.matrix() @ J[Lb]
        H = H + (part if La == Lb else part + part.T)
    return H


def _kinematic_hessian(
    first: dict[int, Any],
    link_of: dict[int, int],
    spheres: list[Sphere],
    state: Any,
    J: dict[int, Any],
    z: Any,
) -> Any:
    """Σ_L ∇²_z(F_L·p_L + <G_L, R_L>): the second derivatives of the kinematics weighted by
    the first-order ones (F_L = Σ f_i, G_L = Σ f_i s_iᵀ held fixed); None without links."""
    syms, vals, weighted = [], [], 0
    for L in sorted(J):
        F, G = ca.SX.sym(f"F{L}", 3), ca.SX.sym(f"G{L}", 3, 3)
        mine = [i for i in first if link_of[i] == L]
        syms += [F, ca.vec(G)]
        vals += [
            sum((first[i] for i in mine), ca.SX.zeros(3)),
            ca.vec(sum((first[i] @ ca.DM(spheres[i].center).T for i in mine), ca.SX.zeros(3, 3))),
        ]
        weighted = weighted + ca.dot(F, state.p[L]) + ca.sum1(ca.sum2(G * state.R[L]))
    if not syms:
        return None
    Hk = ca.hessian(weighted, z)[0]
    return ca.substitute(Hk, ca.vertcat(*syms), ca.vertcat(*vals))


# CollisionTerm.self_groups per (proxy model, pairs); the model is held (Ref)
_GROUPS: BoundedCache[list[Any]] = BoundedCache("collision row groups", 64)


@dataclass
class CollisionTerm(Term):
    """Rows d >= margin for the active sphere pairs and sphere-box pairs (see module doc)."""

    pm: ProxyModel
    self_pairs: tuple[tuple[int, int], ...]
    env_pairs: tuple[tuple[int, int], ...]  # (sphere, box index)
    boxes: list[EnvBox]
    margin: float
    name: str = "collision"

    def key(self) -> tuple[Any, ...]:
        return ("collision", self.self_pairs, self.env_pairs, len(self.boxes))

    def declare(self, ctx: BuildContext) -> None:
        nlp, st = ctx.nlp, ctx.state
        margin = nlp.parameter("collision.margin", 1)
        r = self.pm.radii
        spheres = self.pm.spheres
        if self.self_pairs:
            # self distances do not depend on the base: compute them in the base frame, which
            # keeps the base pose and its exponential map out of these rows' Hessians
            local = ctx.kin.forward(ca.SX.zeros(3), ca.SX.eye(3), ctx.joints)
            used = sorted({i for p in self.self_pairs for i in p})
            c = {i: _center(local, spheres[i]) for i in used}
            pm = self.pm
            held = {}  # per joint pair: how far apart it is held (see _held)
            for i, j in self.self_pairs:
                k = pm.link_index(spheres[i].joint_id, spheres[j].joint_id)
                held.setdefault(k, _held(margin, float(pm.clearance[k])))
            rows = [
                [
                    _pair_element(
                        c, r, i, j, held[pm.link_index(spheres[i].joint_id, spheres[j].joint_id)]
                    )
                    for i, j in members
                ]
                for _, members in self.self_groups()
            ]
            value, deriv = _soft_min_rows(ctx, local, spheres, rows, 0.0, None)
            nlp.constrain("collision.self", value, 0.0, np.inf, deriv)
        if self.env_pairs:
            B = ca.reshape(
                nlp.parameter("collision.boxes", 15 * len(self.boxes)), 15, len(self.boxes)
            )
            used = sorted({i for i, _ in self.env_pairs})
            c = {i: _center(st, spheres[i]) for i in used}
            # saturated: min(d, margin + ENV_SATURATION), smoothly (see ENV_SATURATION)
            rows = [
                [_box_element(c[i], i, B[:, k], r[i]), _Element(margin + ENV_SATURATION)]
                for i, k in self.env_pairs
            ]
            value, deriv = _soft_min_rows(ctx, st, spheres, rows, margin, ctx.base_rotation)
            nlp.constrain("collision.env", value, 0.0, np.inf, deriv)

    def self_groups(self) -> list[tuple[tuple[int, int], list[tuple[int, int]]]]:
        """Active sphere pairs grouped by pair of limbs (:func:`limbs`): one row each.

        Rows per pair of limbs rather than per pair of links: fewer rows make IPOPT's linear
        systems smaller (Talos on talos-near-body-collision: 8 instead of 28 rows, the solve
        about 12 % faster in generated C), and the smooth minimum carries a hand sliding from
        one link of a leg to the next; median iterations were 21.5 and 21.0 on two seeds
        (22.5 and 21.0 per pair of links), mean 24.5 and 22.1 (26.1 and 24.1)."""
        key = (Ref(self.pm), self.self_pairs)
        cached = _GROUPS.get(key)  # the next solves of a structure have the same pairs
        if cached is not None:
            return cached
        limb = self.pm.limb
        groups: dict[tuple[int, int], list[tuple[int, int]]] = {}
        for i, j in self.self_pairs:
            a, b = self.pm.spheres[i].joint_id, self.pm.spheres[j].joint_id
            if limb is not None:
                a, b = int(limb[a]), int(limb[b])
            groups.setdefault((min(a, b), max(a, b)), []).append((i, j))
        return _GROUPS.put(key, sorted(groups.items()))

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {"collision.margin": np.array([self.margin])}
        if self.env_pairs:
            out["collision.boxes"] = np.column_stack(
                [
                    np.concatenate(
                        [b.T_world_box.rotation.ravel(order="F"), b.T_world_box.translation, b.half]
                    )
                    for b in self.boxes
                ]
            )
        return out
