"""Validation of user-given fields (YAML/JSON/Python), each failure one :class:`InputError`."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

from .errors import InputError
from .hints import did_you_mean
from .plausible import check_angle, check_angles


def require_mapping(value: Any, field: str) -> Mapping[str, Any]:
    """The value must be a mapping (YAML dict)."""
    if not isinstance(value, Mapping):
        raise InputError(
            field, f"expected a mapping, got {type(value).__name__}", "write key: value"
        )
    return value


def check_keys(
    value: Mapping[str, Any], field: str, required: Iterable[str], optional: Iterable[str]
) -> None:
    """Every required key present, no unknown key; an unknown key close to an allowed one is
    reported first, as misspelt (``robot_pach: unknown key, did you mean robot_patch?``)."""
    required = list(required)
    allowed = set(required) | set(optional)
    unknown = [key for key in value if key not in allowed]
    listed = f"allowed keys: {', '.join(sorted(allowed))}"
    for key in unknown:
        hint = did_you_mean(str(key), allowed)
        if hint:
            raise InputError(f"{field}.{key}", f"unknown key, {hint}", listed)
    for key in required:
        if key not in value:
            raise InputError(f"{field}.{key}", "missing", f"add '{key}' to {field}")
    for key in unknown:
        raise InputError(f"{field}.{key}", "unknown key", listed)


def number(
    value: Any, field: str, *, minimum: float | None = None, positive: bool = False
) -> float:
    """A finite real number, optionally >= minimum or > 0."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(field, f"expected a number, got {value!r}", "write a finite number")
    x = float(value)
    if not math.isfinite(x):
        raise InputError(field, f"{value!r} is not finite", "write a finite number")
    if positive and x <= 0:
        raise InputError(field, f"must be positive, got {x}", "write a number > 0")
    if minimum is not None and x < minimum:
        raise InputError(field, f"must be >= {minimum}, got {x}", f"write a number >= {minimum}")
    return x


def integer(value: Any, field: str, minimum: int, fix: str) -> int:
    """An integer (not a bool) >= minimum; ``fix``: the hint of the error."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InputError(field, f"expected an integer >= {minimum}, got {value!r}", fix)
    return value


def angle(value: Any, field: str) -> float:
    """A finite angle [rad]; beyond a turn it is most likely degrees: a warning."""
    x = number(value, field)
    check_angle(x, field)
    return x


def vector(value: Any, n: int, field: str) -> np.ndarray:
    """A list of exactly n finite numbers."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, list | tuple):
        raise InputError(
            field, f"expected a list of {n} numbers, got {value!r}", f"write [{n} numbers]"
        )
    if len(value) != n:
        raise InputError(field, f"expected {n} numbers, got {len(value)}", f"write [{n} numbers]")
    return np.array([number(v, f"{field}[{i}]") for i, v in enumerate(value)])


def points2d(value: Any, field: str) -> np.ndarray:
    """A list of [x, y] pairs."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, list | tuple):
        raise InputError(field, "expected a list of [x, y] points", "write [[x, y], ...]")
    return np.array([vector(v, 2, f"{field}[{i}]") for i, v in enumerate(value)]).reshape(-1, 2)


def string(value: Any, field: str) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value:
        raise InputError(field, f"expected a non-empty string, got {value!r}", "write a name")
    return value


def placement(position: Any, rpy: Any, field: str) -> pin.SE3:
    """SE3 from a position (3,) [m] and roll-pitch-yaw angles (3,) [rad]."""
    p = vector(position, 3, f"{field}.position")
    r = vector(rpy, 3, f"{field}.rpy")
    check_angles(r, f"{field}.rpy")
    return pin.SE3(pin.rpy.rpyToMatrix(*r), p)


def read_yaml(path: str | Path, what: str = "file") -> Any:
    """Parse a YAML file (the package's one YAML reader: problem, patch and sequence files), or
    raise an InputError naming the file; ``what`` names the file in the fix."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise InputError(str(path), "no such file", f"give the path of an existing {what}") from exc
    except OSError as exc:
        raise InputError(str(path), f"cannot read it ({exc.strerror})", "check the path") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise InputError(str(path), f"invalid YAML{where}", "fix the YAML syntax") from exc
