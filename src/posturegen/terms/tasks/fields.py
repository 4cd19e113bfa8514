"""The keys of a task's entry (in a problem file, a posture file and Python alike): each
:class:`Field` reads and checks its value (one-line :class:`posturegen.errors.InputError`
naming the key), writes it back to a file, and describes itself in the JSON Schema."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ... import _fields as F
from ...errors import InputError

REQUIRED = object()  # a Field's default when the key must be given


@dataclass(frozen=True)
class Field:
    """One key of a task's entry: its ``form`` (frame, joint_values, vector, direction, number,
    range, rpy, points), its length n for vectors, its default (REQUIRED: must be given; None:
    may be absent) and a line of documentation with the unit."""

    form: str
    doc: str
    n: int = 3
    default: Any = REQUIRED
    minimum: float | None = None

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def read(self, value: Any, fld: str) -> Any:
        """The checked value (numpy arrays for numbers), or an InputError naming ``fld``."""
        if value is None:
            return None
        reader = _READERS[self.form]
        return reader(self, value, fld)

    def write(self, value: Any) -> Any:
        """The value as plain data (lists, floats, strings) for a JSON or YAML file."""
        if value is None:
            return None
        if self.form == "joint_values":
            return {k: _plain(v) for k, v in value.items()}
        return _plain(value)

    def schema(self) -> dict[str, Any]:
        """The key's JSON Schema."""
        out = dict(_SCHEMAS[self.form](self))
        out["description"] = self.doc
        return out


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.floating):
        return float(value)
    return value


def _frame(f: Field, value: Any, fld: str) -> str:
    return F.string(value, fld)


def _vector(f: Field, value: Any, fld: str) -> np.ndarray:
    return F.vector(value, f.n, fld)


def _direction(f: Field, value: Any, fld: str) -> np.ndarray:
    v = F.vector(value, 3, fld)
    norm = float(np.linalg.norm(v))
    if norm < 1e-9:
        raise InputError(fld, "is the zero vector", "write a direction, e.g. [0, 0, 1]")
    return v / norm


def _number(f: Field, value: Any, fld: str) -> float:
    return F.number(value, fld, minimum=f.minimum)


def _range(f: Field, value: Any, fld: str) -> np.ndarray:
    lo_hi = F.vector(value, 2, fld)
    if lo_hi[0] > lo_hi[1]:
        raise InputError(fld, f"lower bound {lo_hi[0]} above upper {lo_hi[1]}", "write [min, max]")
    return lo_hi


def _rpy(f: Field, value: Any, fld: str) -> np.ndarray:
    rpy = F.vector(value, 3, fld)
    F.check_angles(rpy, fld)
    return rpy


def _points(f: Field, value: Any, fld: str) -> np.ndarray:
    return F.points2d(value, fld)


def _joint_values(f: Field, value: Any, fld: str) -> dict[str, float | np.ndarray]:
    v = F.require_mapping(value, fld)
    if not v:
        raise InputError(fld, "is empty", "write {joint_name: value or [min, max], ...}")
    out: dict[str, float | np.ndarray] = {}
    for name, target in v.items():
        key = f"{fld}.{name}"
        out[str(name)] = (
            _range(f, target, key)
            if isinstance(target, list | tuple | np.ndarray)
            else F.number(target, key)
        )
    return out


_READERS = {
    "frame": _frame,
    "vector": _vector,
    "direction": _direction,
    "number": _number,
    "range": _range,
    "rpy": _rpy,
    "points": _points,
    "joint_values": _joint_values,
}

_NUMBER = {"type": "number"}


def _array(n: int) -> dict[str, Any]:
    return {"type": "array", "items": _NUMBER, "minItems": n, "maxItems": n}


_SCHEMAS = {
    "frame": lambda f: {"type": "string"},
    "vector": lambda f: _array(f.n),
    "direction": lambda f: _array(3),
    "number": lambda f: {"type": "number"} | ({} if f.minimum is None else {"minimum": f.minimum}),
    "range": lambda f: _array(2),
    "rpy": lambda f: _array(3),
    "points": lambda f: {"type": "array", "items": _array(2), "minItems": 3},
    "joint_values": lambda f: {
        "type": "object",
        "minProperties": 1,
        "additionalProperties": {"oneOf": [_NUMBER, _array(2)]},
    },
}


def read_fields(fields: Mapping[str, Field], entry: Mapping[str, Any], fld: str) -> dict[str, Any]:
    """Every field's checked value (or its default) from a task's entry."""
    out = {}
    for key, f in fields.items():
        value = entry.get(key)
        out[key] = (
            f.read(value, f"{fld}.{key}")
            if value is not None
            else (None if f.required else f.default)
        )
    return out
