"""Warnings for values that are valid but most likely mistakes: an angle beyond a turn
(degrees written as radians), a task target farther from a contact than the robot reaches
from it (millimetres written as metres), a surface or box of hundreds of metres.

Each is one :class:`~posturegen.errors.ImplausibleValueWarning` (``warnings.warn``) whose
message names the field and the likely fix, like an :class:`~posturegen.errors.InputError`;
the problem is built and solved as given. The reach is an upper bound from the kinematic chain
(:func:`chain_length`), so a warned target is out of reach for sure.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import Any

import numpy as np
import pinocchio as pin

from .errors import ImplausibleValueWarning

TURN = 2 * np.pi
MAX_SCENE_LENGTH = 100.0  # [m] a surface or box larger than this is most likely in mm


def warn(field: str, problem: str, fix: str) -> None:
    """One implausible-value warning: ``field: problem (fix)``."""
    warnings.warn(f"{field}: {problem} ({fix})", ImplausibleValueWarning, stacklevel=3)


def check_angle(value: float, field: str) -> None:
    """Warn for an angle [rad] beyond a turn: most likely degrees."""
    if abs(value) > TURN + 1e-9:
        warn(
            field,
            f"{value:g} rad is more than a turn",
            f"angles are in radians: {value:g}° is {np.radians(value):.6g}",
        )


def check_angles(values: Iterable[float], field: str) -> None:
    """:func:`check_angle` on each of a vector's angles (``field[i]``)."""
    for i, v in enumerate(values):
        check_angle(float(v), f"{field}[{i}]")


def check_size(length: float, field: str, what: str) -> None:
    """Warn for a surface or box ``length`` [m] across beyond MAX_SCENE_LENGTH."""
    if length > MAX_SCENE_LENGTH:
        warn(field, f"the {what} is {length:.4g} m across", "millimetres? lengths are in m")


def chain_length(model: pin.Model, joint_a: int, joint_b: int) -> float:
    """An upper bound [m] of the distance between the origins of two joints over every
    configuration: over the joints j on the tree path between them (below their common
    ancestor), |placement_j| plus the travel of j when it is prismatic, since
    O_j = O_parent + R_parent·(placement_j + axis·q_j)."""

    def up(j: int) -> list[int]:
        chain = []
        while j > 0:
            chain.append(j)
            j = int(model.parents[j])
        return chain

    a, b = up(joint_a), up(joint_b)
    common = set(a) & set(b)
    length = 0.0
    for j in [*a, *b]:
        if j in common:
            continue
        length += float(np.linalg.norm(model.jointPlacements[j].translation))
        if "Prismatic" in model.joints[j].shortname():
            i = model.joints[j].idx_q
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            length += float(max(abs(lo), abs(hi)))
    return length


def check_target(
    robot: Any, frame_name: str, target: Any, contacts: Iterable[Any], field: str
) -> None:
    """Warn when a task's target (3,) [m] is farther from one of the contacts than the task's
    frame can be from that contact's patch (:func:`chain_length`): it cannot be reached."""
    model = robot.model
    frame = model.frames[model.getFrameId(frame_name)]
    target = np.asarray(target, dtype=float)
    worst: tuple[float, float, str] | None = None
    for c in contacts:
        patch = c.patch
        reach = (
            float(np.linalg.norm(frame.placement.translation))
            + chain_length(model, int(frame.parentJoint), patch.joint_id)
            + float(np.linalg.norm(patch.T_joint_patch.translation))
        )
        gap = _distance_to_contact(c, target) - reach
        if gap > 0 and (worst is None or gap > worst[0] - worst[1]):
            worst = (gap + reach, reach, c.name)
    if worst is None:
        return
    distance, reach, name = worst
    # ten times too far, and within reach in mm: most likely millimetres
    millimetres = distance > 10 * reach and distance / 1000 < reach
    fix = "millimetres? targets are in m" if millimetres else "move the target or the contacts"
    warn(
        field,
        f"{np.round(target, 4).tolist()} is {distance:.4g} m from contact '{name}', farther "
        f"than {frame_name} reaches from it ({reach:.2g} m at most)",
        fix,
    )


def _distance_to_contact(contact: Any, point: np.ndarray) -> float:
    """A lower bound [m] of the distance from a world point to where the contact's patch
    origin can be: its pose for a fixed contact, else within the patch's radius of the
    surface polygon (bounded by its circumscribed circle)."""
    T_target = getattr(contact, "T_world_target", None)
    if T_target is not None:
        return float(np.linalg.norm(point - T_target.translation))
    poly = contact.surface.polygon
    centre = contact.surface.to_world(poly.centroid[None])[0]
    radius = float(np.linalg.norm(poly.vertices - poly.centroid, axis=1).max())
    patch_radius = float(np.linalg.norm(contact.patch.polygon.vertices, axis=1).max())
    return max(0.0, float(np.linalg.norm(point - centre)) - radius - patch_radius)
