"""Contacts between a robot patch and a scene surface: the base class, its registry, and the
geometry every type shares. A contact type is one class in one file of this package, registered
under its ``type`` (:func:`register_contact`): it owns its variables (forces, ellipse), its rows,
the keys it reads from a problem file (:meth:`Contact.read`), its posture-file entry and its
own re-check (:meth:`Contact.recheck_outside`).

Frames: the surface frame s has z = the surface's outward normal; the robot patch frame c has
z = the patch's outward normal. In contact the normals are opposite, so a patch at in-plane
position (x, y) and yaw ψ on the surface is ``T_s_c = Trans(x, y, 0)·Rz(ψ)·Rx(π)``.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import casadi as ca
import numpy as np
import pinocchio as pin

from ..._registry import Registry
from ...model.geometry import ConvexPolygon
from ...model.robot import Patch
from ...model.scene import Surface
from ..friction import FrictionModel
from ..nlp import BuildContext, Term
from . import values as V


def patch_in_surface(position: np.ndarray, yaw: float) -> pin.SE3:
    """T_surface_patch = Trans(x, y, 0)·Rz(ψ)·Rx(π) (normals opposite)."""
    R = pin.utils.rotate("z", yaw) @ pin.utils.rotate("x", np.pi)
    return pin.SE3(R, np.array([position[0], position[1], 0.0]))


def polygon_in_surface(patch: Patch, T_surface_patch: pin.SE3) -> ConvexPolygon:
    """The robot patch's polygon expressed in the surface plane (2-D)."""
    v = patch.polygon.vertices
    pts = (
        np.column_stack([v, np.zeros(len(v))]) @ T_surface_patch.rotation.T
        + T_surface_patch.translation
    )
    return ConvexPolygon(pts[:, :2])


def points_in_plane(T: pin.SE3, p_world: np.ndarray) -> np.ndarray:
    """World points (k, 3) [m] in the frame T (its plane: the first two coordinates)."""
    return (np.asarray(p_world, dtype=float) - T.translation) @ T.rotation


@dataclass(frozen=True)
class PlacedContact:
    """A contact's surface and robot patch in the world at a posture (what ``verify``
    re-checks a posture file's contact on)."""

    T_ws: pin.SE3  # surface frame
    P_s: ConvexPolygon  # surface polygon (surface frame)
    T_wc: pin.SE3  # robot patch frame
    P_c: ConvexPolygon  # patch polygon (patch frame)

    @property
    def T_sc(self) -> pin.SE3:
        return self.T_ws.inverse() * self.T_wc


@dataclass(frozen=True)
class ContactEntry:
    """What every contact type reads from its problem-file entry (validated by the reader):
    its name, patch, surface, friction coefficient and model, yaw bounds, CoP margin and grip."""

    name: str
    patch: Patch
    surface: Surface
    mu: float
    friction: FrictionModel
    yaw_range: tuple[float, float] | None
    cop_margin: float  # [m]
    grip: float = 0.0  # [N] (posturegen.terms.forces)


class Contact(Term):
    """A robot patch against a scene surface. A type sets ``kind`` (its ``type`` in files),
    ``keys`` (the problem-file keys it reads beyond robot_patch, surface, type and name, each
    with the JSON Schema of its value: posturegen.terms.contacts.values),
    ``fixed_in_place`` (its patch's pose is given, not found: the collision rules hold the
    links it places, the initial posture is placed on it) and writes :meth:`read`."""

    kind: ClassVar[str]
    keys: ClassVar[Mapping[str, V.Schema]] = {}
    fixed_in_place: ClassVar[bool] = False

    type: str
    name: str
    patch: Patch
    surface: Surface
    mu: float

    @classmethod
    @abstractmethod
    def read(cls, entry: Mapping[str, Any], fld: str, common: ContactEntry) -> Contact:
        """The contact of a problem file's entry (its own keys checked: one-line errors
        naming ``fld``), ``common`` holding what every type reads."""

    @abstractmethod
    def realized_pose(self, model: pin.Model, q: np.ndarray) -> tuple[np.ndarray, float]:
        """(position (2,) [m], yaw [rad]) of the patch in the surface frame at posture q: the
        pose of the fixed contact it becomes for the next stance (a fixed contact: its own)."""

    @staticmethod
    def recheck_outside(entry: Mapping[str, Any], f: PlacedContact) -> float:
        """[m] how far what this type keeps inside the surface lies outside it, from a posture
        file's entry (the force points and the ellipse are re-checked for every type)."""
        return 0.0

    def force_points_count(self) -> int:
        """Number of force-bearing points (0 for contacts that bear no force)."""
        return 0

    def fingerprint(self) -> tuple[Any, ...]:
        """The key (which names the patch) and the patch's geometry, which the declaration
        reads: its joint, its placement on it and its polygon."""
        patch = self.patch
        return (*self.key(), patch.joint_id, patch.T_joint_patch, patch.polygon.vertices)

    @abstractmethod
    def to_dict(self, outputs: dict[str, np.ndarray]) -> dict[str, Any]:
        """The posture file's entry for this contact, from the solution's outputs."""

    def _base_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "type": self.type,
            "mu": self.mu,
            "robot_patch": {
                "name": self.patch.name,
                "frame": self.patch.frame,
                "placement": self.patch.T_frame_patch.homogeneous.tolist(),
                "vertices": self.patch.polygon.vertices.tolist(),
            },
            "surface": self.surface.to_dict(),
            "ellipse": None,
            "forces": [],
        }


def declare_patch_frame(ctx: BuildContext, patch: Patch) -> tuple[ca.SX, ca.SX]:
    """(R_world_patch (3,3), p_world_patch (3,)) as expressions of q."""
    R_j, p_j = ctx.state.R[patch.joint_id], ctx.state.p[patch.joint_id]
    T = patch.T_joint_patch
    return R_j @ T.rotation, p_j + R_j @ T.translation


# ---------------------------------------------------------------------------- registry
_CONTACTS: Registry[type[Contact]] = Registry("contact")
C = TypeVar("C", bound=type[Contact])


def register_contact(cls: C) -> C:
    """Register a contact class under its ``kind`` (a decorator): problem files, the schema,
    ``verify`` and the climbs then know it. Another class under a known kind is an error."""
    return _CONTACTS.register(cls)


def contact_types() -> dict[str, type[Contact]]:
    """The registered contact classes by their ``type`` name, in registration order."""
    return _CONTACTS.types()


def contact_class(kind: Any, fld: str) -> type[Contact]:
    """The class of a problem file's contact ``type`` (one-line error for an unknown one)."""
    return _CONTACTS.lookup(kind, fld)
