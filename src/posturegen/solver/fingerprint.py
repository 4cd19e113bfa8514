"""A program structure's fingerprint: a digest of everything its declaration reads, computed
without declaring it, so that another process finds the structure's compiled library (and its
layout) on disk without building the symbolic program (11-15 ms) nor serializing it to hash
its content (~13 ms; :func:`posturegen.solver.codegen.library_key`).

The fingerprint is the SHA-256 of, in order: the package's Python sources (the code that
declares), the robot's Pinocchio model (its serialized text: joints, inertias, limits, frames),
each term's :meth:`~posturegen.terms.nlp.Term.fingerprint` (its structure key with the values
it names by reference, a contact's patch or the collision rows' pair list), the elastic
relaxation. Values are encoded by type, exactly (floats by their shortest round-trip repr,
arrays by dtype, shape and bytes), never by ``repr`` of an object (an array's repr elides).

A structure has no fingerprint (None: the library is then found by its content) when one of
its terms is defined outside posturegen (its declaration is code the sources' digest does not
cover) or its fingerprint holds a value of a type this module cannot encode."""

from __future__ import annotations

import dataclasses
import enum
import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .._cache import BoundedCache, Ref, memoize

PACKAGE = __name__.split(".")[0]

# per robot model (held): the digest of its serialized model (2.6 ms for Talos)
_MODELS: BoundedCache[str] = BoundedCache("model digests", 8)


@memoize("source digest", 1)
def source_digest() -> str:
    """SHA-256 (16 hex digits) of the package's Python sources."""
    h = hashlib.sha256()
    root = Path(__file__).parent.parent
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode() + path.read_bytes())
    return h.hexdigest()[:16]


class NotEncodable(Exception):
    """A value without an exact encoding (the structure gets no fingerprint)."""


def encode(value: Any, h: Any) -> None:
    """Feed an exact, type-tagged encoding of ``value`` into the hash ``h``; raise
    :class:`NotEncodable` for a type outside: None, bool, int, float, str, bytes, tuples and
    lists, dicts, numpy arrays and scalars, enums, dataclasses and pinocchio SE3."""
    if value is None or isinstance(value, (bool, int, float, str)):
        h.update(f"{type(value).__name__}:{value!r};".encode())
    elif isinstance(value, bytes):
        h.update(b"bytes:%d:" % len(value) + value)
    elif isinstance(value, (tuple, list)):
        h.update(f"{type(value).__name__}[{len(value)}]".encode())
        for item in value:
            encode(item, h)
    elif isinstance(value, dict):
        h.update(f"dict[{len(value)}]".encode())
        for k, v in value.items():
            encode(k, h)
            encode(v, h)
    elif isinstance(value, (np.ndarray, np.generic)):
        array = np.ascontiguousarray(value)
        if array.dtype == object:
            raise NotEncodable("an array of objects")
        h.update(f"array:{array.dtype.str}:{array.shape};".encode())
        h.update(array.tobytes())
    elif isinstance(value, enum.Enum):
        h.update(f"enum:{type(value).__qualname__}.{value.name};".encode())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        h.update(f"dataclass:{type(value).__module__}.{type(value).__qualname__}".encode())
        for f in dataclasses.fields(value):
            encode(f.name, h)
            encode(getattr(value, f.name), h)
    elif isinstance(value, pin.SE3):
        encode(value.homogeneous, h)
    else:
        raise NotEncodable(type(value).__name__)


def model_digest(model: pin.Model) -> str:
    """SHA-256 (hex) of a Pinocchio model's serialized text (cached per model object)."""
    return _MODELS.get_or_make(
        Ref(model), lambda: hashlib.sha256(model.saveToString().encode()).hexdigest()
    )


def structure_fingerprint(program: Any) -> str | None:
    """The fingerprint (32 hex digits) of ``program``'s structure
    (:class:`posturegen.solver.problem.Program`), None when it has none (see the module)."""
    terms = program.terms()
    if any(type(t).__module__.split(".")[0] != PACKAGE for t in terms):
        return None
    h = hashlib.sha256()
    try:
        encode((source_digest(), model_digest(program.robot.model)), h)
        encode([t.fingerprint() for t in terms], h)
        encode(program.elastic, h)
    except NotEncodable:
        return None
    return h.hexdigest()[:32]
