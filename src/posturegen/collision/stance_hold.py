"""How far apart the links that carry the fixed contacts can be held: the distances of their
proxies standing on the problem's own fixed contacts.

A pair of joints whose proxies are closer than the margin at the reference posture is held
no closer than there (:meth:`posturegen.proxies.ProxyModel.pair_clearance`), so that the
reference stays feasible. Feet fixed elsewhere than at the reference move the legs: Talos'
legs (6 joints each between a fixed sole and the base) keep no freedom but the base's, and a
narrow stance with its feet yawed puts the thighs and knees closer than at half-sitting, and
closer than the margin. Held at the margin there, the program had no feasible point:
12 forward reaches, feet 16 cm apart at yaws 0.045 and 0.109 rad, margin 5 mm: all 12
failed after 180-440 IPOPT iterations (the knees' proxies came 1 mm apart in the solution
without collision rows; meshes apart). Here each pair of joints on the chains from the base
to the fixed contacts is held no farther apart than in the *stance posture*: the initial
posture with those chains' joints solved (damped least squares) to put each fixed patch on
its target. The mesh check (posturegen.verify) still tests every pair.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref
from ..model.kinematics import scratch_data
from ..model.robot import Robot
from ..terms.contacts import FixedContact
from .proxies import SLIDE, ProxyModel

IK_STEPS = 30  # damped least-squares steps of the stance posture
IK_TOL = 1e-6  # [m, rad] the patch error at which they stop
IK_DAMPING = 1e-6
# [m] a hold above this is no cap (how far apart proxies on chains ever need to be held)
NO_CAP = 1.0
DETERMINED = 6  # joints between the base and a fixed patch whose stance posture counts
STANDS = 1e-4  # [m, rad] a stance posture whose patches are farther from their targets: no caps
# [m] the caps are those of the pairs closer than this in the stance posture: a pair farther
# apart needs none for any margin up to it (its hold is at most the margin); larger margins
# ask for caps of that reach. Talos: the search among 50 leg joint pairs within their
# reference clearances (up to 0.67 m) took 2.5 ms, within 10 cm 1.3 ms; a new stance's caps
# 6.2 -> 3.4 ms in all (with the thread's scratch data instead of three createData)
CAP_REACH = 0.1

# per robot model, proxy model, q_init, fixed patches (joint, placement on it) and their
# targets, and reach: all that _caps reads
_CAPS: BoundedCache[np.ndarray] = BoundedCache("stance caps", 64)
# per proxy model and chain: the candidate joint pairs on the chain
_LINKS: BoundedCache[np.ndarray] = BoundedCache("joint pairs on a chain", 16)


def support_joints(model: pin.Model, contact_joints: Sequence[int]) -> set[int]:
    """The joints on the chains from the base to ``contact_joints`` (the base included)."""
    out: set[int] = set()
    for j in contact_joints:
        while j > 0:
            out.add(j)
            j = int(model.parents[j])
    return out


def stance_posture(robot: Robot, q: np.ndarray, fixed: Sequence[FixedContact]) -> np.ndarray:
    """q (nq,) with the joints of the chains to the fixed contacts moved so that each patch
    frame lies on its target: Δq = Jᵀ(JJᵀ + λI)⁻¹e stacked over the contacts, e = log6 of
    the patch's pose to its target (local), the base held; clipped to the joint limits."""
    model = robot.model
    data = scratch_data(model)
    q = np.array(q, dtype=float)
    chain = support_joints(model, [c.patch.joint_id for c in fixed])
    cols = np.array(
        sorted(model.joints[j].idx_v for j in chain if j > 1 and model.joints[j].nv == 1),
        dtype=int,
    )
    rows_q = np.array([model.joints[j].idx_q for j in range(2, model.njoints)], dtype=int)
    rows_v = np.array([model.joints[j].idx_v for j in range(2, model.njoints)], dtype=int)
    qv = dict(zip(rows_v.tolist(), rows_q.tolist(), strict=True))
    cols_q = np.array([qv[int(v)] for v in cols], dtype=int)
    if cols.size == 0:
        return q
    for _ in range(IK_STEPS):
        pin.forwardKinematics(model, data, q)
        errors, jacobians = [], []
        for c in fixed:
            T_patch = data.oMi[c.patch.joint_id] * c.patch.T_joint_patch
            errors.append(pin.log6(T_patch.actInv(c.T_world_target)).vector)
            J = pin.computeJointJacobian(model, data, q, c.patch.joint_id)  # (6, nv) local
            jacobians.append(c.patch.T_joint_patch.inverse().action @ J[:, cols])
        e, A = np.concatenate(errors), np.vstack(jacobians)
        if np.abs(e).max() < IK_TOL:
            break
        q[cols_q] += A.T @ np.linalg.solve(A @ A.T + IK_DAMPING * np.eye(len(e)), e)
        q[7:] = np.clip(q[7:], robot.q_lower, robot.q_upper)
    return q


def stance_caps(problem: Any, pm: ProxyModel, reach: float = CAP_REACH) -> np.ndarray:
    """(P,) [m] the largest hold of each candidate joint pair: for a pair of joints both on
    the chains to the fixed contacts whose proxies are closer in the stance posture than at
    the reference and than ``reach``, that distance (minus SLIDE when they overlap there, as
    at the reference); NO_CAP for the others. Exact for margins up to ``reach``.

    Only the chains that the contacts determine count: at most 6 joints between the base
    and the patch (Talos' and HRP-2's legs); a longer chain (an arm and the torso holding a
    rung) has postures to spare, and the one the least squares pick says nothing of how
    close its links must come (capped there, ladder scenes failed the mesh check). No caps
    either when the stance posture does not reach its targets (STANDS)."""
    model = problem.robot.model
    fixed = [
        c
        for c in problem.contacts
        if c.fixed_in_place and len(support_joints(model, [c.patch.joint_id])) - 1 <= DETERMINED
    ]
    key = (
        Ref(problem.robot.model),
        Ref(pm),
        np.asarray(problem.q_init, dtype=float).tobytes(),
        tuple(
            (
                c.patch.joint_id,
                c.patch.T_joint_patch.homogeneous.tobytes(),
                c.T_world_target.homogeneous.tobytes(),
            )
            for c in fixed
        ),
        reach,
    )
    return _CAPS.get_or_make(key, lambda: _caps(problem, pm, fixed, reach))


def _caps(problem: Any, pm: ProxyModel, fixed: list[FixedContact], reach: float) -> np.ndarray:
    """:func:`stance_caps` computed."""
    model = problem.robot.model
    caps = np.full(len(pm.joint_pairs), NO_CAP)
    chain = frozenset(support_joints(model, [c.patch.joint_id for c in fixed]))
    links = _LINKS.get_or_make((Ref(pm), chain), lambda: _links_on(pm, chain))
    q = stance_posture(problem.robot, problem.q_init, fixed) if fixed and len(links) else None
    if q is not None and _patch_error(model, q, fixed) < STANDS:
        data = scratch_data(model)
        pin.forwardKinematics(model, data, q)
        centers = pm.centers_world(model, data)
        # only pairs closer than at the reference and than the reach
        slack = np.minimum(np.maximum(pm.clearance, 0.0), reach) + 1e-9
        close = pm.close_pairs(centers, slack, links)
        for k in np.unique(close.link):
            d = float(close.d[close.link == k].min())
            caps[k] = d - SLIDE if d < 0 else d
    caps.flags.writeable = False  # shared by every solve of this stance
    return caps


def _links_on(pm: ProxyModel, chain: frozenset[int]) -> np.ndarray:
    """Indices of the candidate joint pairs whose joints are both in ``chain``."""
    on = [k for k, (a, b) in enumerate(pm.joint_pairs) if int(a) in chain and int(b) in chain]
    return np.array(on, dtype=int)


def _patch_error(model: pin.Model, q: np.ndarray, fixed: Sequence[FixedContact]) -> float:
    """The largest |log6| [m, rad] of a fixed patch's pose to its target at q."""
    data = scratch_data(model)
    pin.forwardKinematics(model, data, q)
    return max(
        float(
            np.abs(
                pin.log6(
                    (data.oMi[c.patch.joint_id] * c.patch.T_joint_patch).actInv(c.T_world_target)
                ).vector
            ).max()
        )
        for c in fixed
    )


def held_clearance(problem: Any, pm: ProxyModel, margin: float) -> np.ndarray:
    """(P,) [m] how far apart each candidate joint pair is held in ``problem``: the
    reference's rule (ProxyModel.pair_clearance), capped by :func:`stance_caps`."""
    caps = stance_caps(problem, pm, max(CAP_REACH, margin))
    return np.minimum(pm.pair_clearance(margin), caps)
