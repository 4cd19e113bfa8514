"""The first start of a collision solve: the joints that carry no contact moved so that the
pairs pressed together at the initial posture are a little apart
(:func:`separated_start`)."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..model.kinematics import scratch_data
from ..model.robot import Robot
from .broad_phase import Close
from .proxies import ProxyModel

SEPARATION = 0.03  # [m] how far above its clearance the first start puts each close pair
SEPARATED_PER_LINK = 2  # the closest sphere pairs of each joint pair that the start parts
# steps of the start, each at most this far on any joint [rad]: a full step moved Talos' left
# shoulder far enough to put its wrist 3 cm into its thigh, unseen until the next step
SEPARATION_STEPS = 6
SEPARATION_STEP = 0.1


def _support(model: pin.Model, contact_joints: list[int]) -> set[int]:
    """The joints on a chain from the base to a contact joint (the base's included)."""
    support: set[int] = set()
    for j in contact_joints:
        while j > 0:
            support.add(j)
            j = int(model.parents[j])
    return support


def _free_joints(model: pin.Model, support: set[int]) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and configuration indices of the one-coordinate joints that are not in
    ``support`` (the chains from the base to the contact joints)."""
    free = [j for j in range(2, model.njoints) if j not in support and model.joints[j].nq == 1]
    movable = np.array([model.joints[j].idx_v for j in free], dtype=int)
    return movable, np.array([model.joints[j].idx_q for j in free], dtype=int)


def _moved_links(pm: ProxyModel, links: np.ndarray, support: set[int]) -> np.ndarray:
    """The joint pairs of ``links`` that a free joint moves: a pair of links both in
    ``support`` (the contacts' chains) has a zero gradient on the free joints (it never made
    a row)."""
    ends = np.isin(pm.joint_pairs[links], sorted(support))  # (k, 2)
    return np.asarray(links)[~(ends[:, 0] & ends[:, 1])]


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
    half-sitting Talos' forearms are 4 mm above the 1 cm margin from its thighs:
    talos-near-body-collision took 26.5 and 24.5 median iterations (two seeds), 25.0 and 23.5
    from the separated start, 22.5 and 21.0 with it and COLLISION_MU_INIT = 1e-3."""
    key = (  # all of q: see _SEPARATED
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
    data = scratch_data(model)
    support = _support(model, contact_joints)
    movable, movable_q = _free_joints(model, support)
    q = np.array(q, dtype=float)
    if movable.size == 0 or len(links) == 0:
        return q[7:]  # nothing to part: not worth a cache entry
    held = pm.pair_clearance(margin)  # (P,) pairs tighter at the reference are left there
    target = np.where(pm.clearance < margin, held, held + SEPARATION)
    links = _moved_links(pm, links, support)
    for _ in range(SEPARATION_STEPS):
        pin.forwardKinematics(model, data, q)
        centers = pm.centers_world(model, data)
        near = pm.closest_pairs(centers, target, SEPARATED_PER_LINK, links)
        if len(near.d) == 0:
            break
        pin.computeJointJacobians(model, data, q)
        system = _shortfalls(model, data, pm, centers, near, movable, target)
        if system is None:
            break
        A, b = system
        step = A.T @ np.linalg.solve(A @ A.T + 1e-4 * np.eye(len(b)), b)
        q[movable_q] += step * min(1.0, SEPARATION_STEP / max(np.abs(step).max(), 1e-12))
        q[7:] = np.clip(q[7:], robot.q_lower, robot.q_upper)
    _SEPARATED.put(key, q[7:].copy())
    return q[7:]


def _shortfalls(
    model: pin.Model,
    data: pin.Data,
    pm: ProxyModel,
    centers: np.ndarray,
    near: Close,
    movable: np.ndarray,
    target: np.ndarray,
) -> tuple[np.ndarray, np.ndarray] | None:
    """(A (k, m), b (k,)): the gradients on the ``movable`` joints (m,) of the ``near``
    sphere pairs that the free joints can part, and how far each is below its joint pair's
    ``target`` [m] (joint Jacobians already in ``data``); None when there is no such pair.

    Pair by pair: computed for all pairs at once (einsum over stacked Jacobians, 185 -> 102 µs
    a step, 2026-12-05), the starts moved by ~1e-13 and IPOPT then failed HRP-2's vertical
    ladder climb at "left foot on rung 6" and the rail_step plan, both verified from these."""
    rows, short = [], []
    jacobians: dict[int, np.ndarray] = {}  # per joint: its Jacobian, fetched once a step
    for i, j, link, dk in zip(near.i, near.j, near.link, near.d, strict=True):
        grad = _pair_gradient(model, data, pm, centers, (int(i), int(j)), jacobians)
        if np.linalg.norm(grad[movable]) > 1e-6:  # pairs the free joints can part
            rows.append(grad[movable])
            short.append(target[link] - dk)
    if not rows:
        return None
    return np.array(rows), np.array(short)


def _pair_gradient(
    model: pin.Model,
    data: pin.Data,
    pm: ProxyModel,
    centers: np.ndarray,
    pair: tuple[int, int],
    jacobians: dict[int, np.ndarray],
) -> np.ndarray:
    """(nv,) the gradient of |c_i - c_j| - r_i - r_j: n·(J_i - J_j), n the unit vector from
    c_j to c_i, J the sphere centres' Jacobians (joint Jacobians already in ``data``;
    ``jacobians`` holds each joint's (6, nv) in LOCAL_WORLD_ALIGNED once fetched)."""
    i, j = pair
    n = centers[i] - centers[j]
    n /= max(math.sqrt(n.dot(n)), 1e-12)  # np.linalg.norm's own sum, without its checks
    grad = np.zeros(model.nv)
    for s, sign in ((i, 1.0), (j, -1.0)):
        jid = pm.spheres[s].joint_id
        J = jacobians.get(jid)
        if J is None:
            J = jacobians[jid] = pin.getJointJacobian(model, data, jid, pin.LOCAL_WORLD_ALIGNED)
        lever = centers[s] - data.oMi[jid].translation
        grad += sign * (n @ (J[:3] - pin.skew(lever) @ J[3:]))
    return grad


# separated starts per (model, q, margin, contacts, links). The base pose moves no self
# distance, but keyed on q's joints alone a start cached by one problem differed by ~1e-15
# (rounding moved a borderline pair) from what the next problem with the same joints computed,
# and a stage of HRP-2's vertical ladder failed after plans had filled the cache: keyed on all
# of q, a start is what its problem computes (tests/test_separation_key.py). Computed with the
# base at the origin instead (a function of the joints, cacheable across the stances of
# talos-stances-collision: 26 ms a call), the start moved by ~1e-16, and ATLAS' 4-step stairs
# plan, reached from the world-frame start, was not (the solver's path flipped): kept here
_SEPARATED: BoundedCache[np.ndarray] = BoundedCache("separated starts", 64)
