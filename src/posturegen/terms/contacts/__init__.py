"""The contact types, one class per file, each registered under its ``type``
(:func:`register_contact`): ``fixed``, ``geometric``, ``support``, ``inclusive``, ``point``
(that order: the problem file's and the schema's)."""

from .base import (
    Contact,
    ContactEntry,
    PlacedContact,
    contact_class,
    contact_types,
    declare_patch_frame,
    patch_in_surface,
    polygon_in_surface,
    register_contact,
)
from .ellipse import EllipseContact
from .fixed import FixedContact
from .floating import FloatingContact
from .geometric import GeometricContact
from .inclusive import InclusiveContact
from .point import PointContact
from .support import SupportContact

__all__ = [
    "Contact",
    "ContactEntry",
    "PlacedContact",
    "EllipseContact",
    "FixedContact",
    "FloatingContact",
    "GeometricContact",
    "InclusiveContact",
    "PointContact",
    "SupportContact",
    "contact_class",
    "contact_types",
    "declare_patch_frame",
    "patch_in_surface",
    "polygon_in_surface",
    "register_contact",
]
