"""Which link pairs self-collision leaves unchecked, and why: the one rule that both the
program's candidate pairs (posturegen.collision.rows) and the mesh check (posturegen.verify) use.

A *link* here is a joint's rigid body: all the collision geometry attached to the joint.
A pair of links is unchecked for exactly one of these reasons, computed from the robot
itself (its model, collision geometry and SRDF) and nothing else:

- ``adjacent``: one joint, or a parent and its child joint (their links touch by design);
- ``srdf``: the SRDF disables every collision pair between their geometries;
- ``reference_overlap``: their meshes overlap (coal) at the robot's reference posture, the
  SRDF's ``half_sitting``, else the neutral posture (MoveIt's "default" rule: no posture
  near the reference could tell them apart);
- ``user``: the problem's ``collision_exclude`` (the only reason a posture file carries that
  verify does not recompute).

Every other pair is avoided by the program and checked on the meshes. An SRDF that disables
only some geometry pairs of two links leaves the others checked (the program avoids the whole
pair: its proxies cover all of both links).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref

REASONS = ("adjacent", "srdf", "reference_overlap", "user")
REFERENCE_NAME = "half_sitting"  # the SRDF posture that is the reference, when there is one


def adjacent_joints(model: pin.Model, a: int, b: int) -> bool:
    """Joints a and b are one joint, or parent and child: their links touch by design and are
    never checked against each other."""
    return a == b or model.parents[a] == b or model.parents[b] == a


def reference_configuration(model: pin.Model, srdf: str | None) -> np.ndarray:
    """q (nq,) of the reference posture: the SRDF's ``half_sitting``, else the neutral one."""
    if srdf:
        probe = pin.Model(model)
        try:
            pin.loadReferenceConfigurations(probe, str(srdf), False)
        except (ValueError, RuntimeError):
            pass  # an SRDF without reference postures (or an unreadable one): neutral
        for entry in probe.referenceConfigurations:
            if str(entry.key()) == REFERENCE_NAME:
                return np.array(entry.data(), dtype=float)
    return pin.neutral(model)


def joint_pair(a: int, b: int) -> tuple[int, int]:
    """The pair (a, b) sorted."""
    return (a, b) if a <= b else (b, a)


@dataclass(frozen=True)
class PairRule:
    """The unchecked pairs of a robot (every reason but ``user``) and the geometry pairs the
    SRDF disables, computed by :func:`pair_rule`."""

    unchecked: dict[tuple[int, int], str]  # sorted joint ids -> reason
    srdf_disabled: frozenset[tuple[int, int]]  # geometry object pairs (sorted indices)
    reference_q: np.ndarray  # (nq,) the reference posture

    def reason(self, a: int, b: int) -> str | None:
        """Why joints a and b are not checked, or None when they are."""
        return self.unchecked.get(joint_pair(a, b))

    def checked_geometry_pairs(
        self, geometry: pin.GeometryModel, user: frozenset[tuple[int, int]] = frozenset()
    ) -> list[tuple[int, int]]:
        """The geometry object pairs (i, j), i < j, that the mesh check tests: those of
        checked joint pairs, minus the user's pairs and the SRDF's disabled geometry pairs."""
        parent = [int(o.parentJoint) for o in geometry.geometryObjects]
        out = []
        for i in range(len(parent)):
            for j in range(i + 1, len(parent)):
                key = joint_pair(parent[i], parent[j])
                if key in self.unchecked or key in user or (i, j) in self.srdf_disabled:
                    continue
                out.append((i, j))
        return out


# pair_rule per (model, geometry, SRDF); the model and geometry are held (Ref)
_RULES: BoundedCache[PairRule] = BoundedCache("pair rules", 16)


def pair_rule(model: pin.Model, geometry: pin.GeometryModel, srdf: str | None) -> PairRule:
    """The unchecked joint pairs of a robot and their reasons (see the module doc)."""
    key = (Ref(model), Ref(geometry), str(srdf) if srdf else None)
    hit = _RULES.get(key)
    if hit is not None:
        return hit
    parent = [int(o.parentJoint) for o in geometry.geometryObjects]
    disabled = _srdf_disabled(model, geometry, srdf)
    by_joints: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for i in range(len(parent)):
        for j in range(i + 1, len(parent)):
            by_joints.setdefault(joint_pair(parent[i], parent[j]), []).append((i, j))
    q_ref = reference_configuration(model, srdf)
    unchecked: dict[tuple[int, int], str] = {}
    for (a, b), pairs in by_joints.items():
        if adjacent_joints(model, a, b):
            unchecked[(a, b)] = "adjacent"
        elif all(p in disabled for p in pairs):
            unchecked[(a, b)] = "srdf"
    overlapping = _overlapping(
        model, geometry, q_ref, [p for k, ps in by_joints.items() if k not in unchecked for p in ps]
    )
    for i, j in overlapping:
        unchecked.setdefault(joint_pair(parent[i], parent[j]), "reference_overlap")
    rule = PairRule(unchecked, frozenset(disabled), q_ref)
    return _RULES.put(key, rule)


def _srdf_disabled(
    model: pin.Model, geometry: pin.GeometryModel, srdf: str | None
) -> set[tuple[int, int]]:
    """Geometry object pairs (sorted indices) that the SRDF disables."""
    if not srdf:
        return set()
    gm = geometry.copy()
    gm.addAllCollisionPairs()
    everything = {joint_pair(int(p.first), int(p.second)) for p in gm.collisionPairs}
    pin.removeCollisionPairs(model, gm, str(srdf), False)
    return everything - {joint_pair(int(p.first), int(p.second)) for p in gm.collisionPairs}


def _overlapping(
    model: pin.Model, geometry: pin.GeometryModel, q: np.ndarray, pairs: list[tuple[int, int]]
) -> list[tuple[int, int]]:
    """The geometry pairs among ``pairs`` whose meshes collide (coal) at posture q."""
    data = model.createData()
    gdata = geometry.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, geometry, gdata)
    out = []
    request = coal.CollisionRequest()
    for i, j in pairs:
        result = coal.CollisionResult()
        Mi, Mj = gdata.oMg[i], gdata.oMg[j]
        if coal.collide(
            geometry.geometryObjects[i].geometry,
            coal.Transform3s(Mi.rotation, Mi.translation),
            geometry.geometryObjects[j].geometry,
            coal.Transform3s(Mj.rotation, Mj.translation),
            request,
            result,
        ):
            out.append((i, j))
    return out


# unchecked_entries per (model, geometry, rule, user pairs): every posture of a robot lists
# the same (Talos: 3 ms of each whole call); the objects are held
_UNCHECKED: BoundedCache[list[dict[str, Any]]] = BoundedCache("unchecked pairs", 16)


def unchecked_entries(
    model: pin.Model,
    geometry: pin.GeometryModel,
    rule: PairRule,
    user: frozenset[tuple[int, int]] = frozenset(),
) -> list[dict[str, Any]]:
    """The posture file's ``collision.unchecked``: every unchecked pair of joints that carry
    geometry, ``{"pair": [joint, joint], "reason": ...}``, sorted by reason then names (a
    fresh copy of the entries listed once per robot and user pairs)."""
    key = (Ref(model), Ref(geometry), Ref(rule), user)
    listed = _UNCHECKED.get_or_make(key, lambda: _unchecked(model, geometry, rule, user))
    return [{"pair": list(e["pair"]), "reason": e["reason"]} for e in listed]


def _unchecked(
    model: pin.Model,
    geometry: pin.GeometryModel,
    rule: PairRule,
    user: frozenset[tuple[int, int]],
) -> list[dict[str, Any]]:
    """:func:`unchecked_entries`, listed."""
    carrying = sorted({int(o.parentJoint) for o in geometry.geometryObjects})
    out = []
    for i, a in enumerate(carrying):
        for b in carrying[i + 1 :]:
            key = joint_pair(a, b)
            reason = rule.unchecked.get(key) or ("user" if key in user else None)
            if reason is not None:
                out.append({"pair": sorted([model.names[a], model.names[b]]), "reason": reason})
    count = np.bincount([int(o.parentJoint) for o in geometry.geometryObjects])
    for a in np.flatnonzero(count > 1):  # a joint's own objects with each other
        out.append({"pair": [model.names[int(a)]] * 2, "reason": "adjacent"})
    return sorted(out, key=lambda e: (REASONS.index(e["reason"]), e["pair"]))
