"""The JSON Schema of the problem file (``posturegen schema``), generated from what the reader
accepts: the top-level and option keys, each contact type's keys, and every registered task
type's keys (:func:`posturegen.terms.tasks.task_types`, a user's own included). Editors that
read JSON Schema (VS Code's YAML extension, for one) complete and check problem files with it;
``posturegen schema --validate FILE...`` checks files against it. The reader stays the
authority: it also checks what a schema cannot (frames of the robot, polygons convex)."""

from __future__ import annotations

import argparse
import importlib.resources
import json
import sys
from pathlib import Path
from typing import Any

import jsonschema

from .._fields import read_yaml
from ..solver import codegen
from ..terms.contacts import contact_types
from ..terms.contacts.values import FRICTION
from ..terms.tasks import task_types

SCHEMA_ID = "https://posturegen.dev/schema/problem.json"
_NUMBER: dict[str, Any] = {"type": "number"}


def _array(n: int, items: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"type": "array", "items": items or _NUMBER, "minItems": n, "maxItems": n}


_POINTS = {"type": "array", "items": _array(2), "minItems": 3}
_SURFACE = {
    "type": "object",
    "properties": {
        "name": {"type": "string"},
        "position": _array(3),
        "rpy": _array(3),
        "vertices": _POINTS,
        "thickness": {"type": "number", "minimum": 0},
    },
    "required": ["name", "vertices"],
    "additionalProperties": False,
}
_OBSTACLE = {
    "type": "object",
    "properties": {
        "name": {"type": "string"},
        "box": _array(3),
        "position": _array(3),
        "rpy": _array(3),
    },
    "required": ["name", "box"],
    "additionalProperties": False,
}
_SOLVER = {
    "type": "object",
    "properties": {
        "tol": {"type": "number", "exclusiveMinimum": 0},
        "max_iter": {"type": "integer", "minimum": 1},
        "max_call_iter": {"type": "integer", "minimum": 1},
        "max_cpu_time": {"type": "number", "exclusiveMinimum": 0},
        "print_level": {"type": "integer"},
        "jit": {"type": "boolean"},
        "codegen": {"enum": list(codegen.MODES)},
        "method": {"enum": ["ipopt", "sqp", "auto"]},
        "qp": {"enum": ["daqp", "proxsuite"]},
    },
    "additionalProperties": False,
}
_OPTIONS = {
    "type": "object",
    "properties": {
        "initial": {"oneOf": [{"type": "string"}, {"type": "object"}, {"type": "array"}]},
        "self_collision": {"type": "boolean"},
        "solver": _SOLVER,
        "torque_limit_scale": {"type": "number", "exclusiveMinimum": 0},
        "environment_collision": {"enum": [True, False, "auto"]},
        "collision_margin": {"type": "number", "minimum": 0},
        "collision_exclude": {"type": "array", "items": _array(2, {"type": "string"})},
        "cop_margin": {"type": "number", "minimum": 0},
    },
    "additionalProperties": False,
}
_COSTS = {
    "type": "object",
    "properties": {
        "posture": {"type": "number", "minimum": 0},
        "posture_reference": {"enum": ["initial", "default"]},
        "forces": {"type": "number", "minimum": 0},
        "torques": {"type": "number", "minimum": 0},
    },
    "additionalProperties": False,
}


def _contact(kind: str) -> dict[str, Any]:
    keys = contact_types()[kind].keys
    return {
        "type": "object",
        "title": f"{kind} contact",
        "properties": {
            "type": {"const": kind},
            "robot_patch": {"type": "string", "description": "a patch of the robot"},
            "surface": {"type": "string", "description": "a surface of the scene"},
            "name": {"type": "string"},
            **dict(keys),  # each key with its value's schema (the type's own)
        },
        "required": ["type", "robot_patch", "surface"],
        "additionalProperties": False,
    }


def _task(kind: str) -> dict[str, Any]:
    cls = task_types()[kind]
    return {
        "type": "object",
        "title": f"{kind} task",
        "description": (cls.__doc__ or "").strip().split("\n\n")[0],
        "properties": {
            "type": {"const": kind},
            **{k: f.schema() for k, f in cls.fields.items()},
            "weight": {
                "type": ["number", "null"],
                "exclusiveMinimum": 0,
                "description": "soft: the cost's weight (absent: a hard constraint)",
            },
            "tolerance": {"type": "number", "minimum": 0, "description": "hard: rows met within"},
        },
        "required": ["type", *(k for k, f in cls.fields.items() if f.required)],
        "additionalProperties": False,
    }


def problem_schema(user_tasks: bool = True) -> dict[str, Any]:
    """The problem file's JSON Schema (draft 2020-12), with every registered task type (only
    posturegen's own when not ``user_tasks``: the file shipped in the package)."""
    kinds = sorted(
        k for k, c in task_types().items() if user_tasks or c.__module__.startswith("posturegen.")
    )
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": "posturegen problem file",
        "type": "object",
        "properties": {
            "robot": {"oneOf": [{"type": "string"}, {"type": "object"}]},
            "name": {"type": "string"},
            "description": {"type": "string"},
            "mu": {"type": "number", "minimum": 0},
            "friction": FRICTION,
            "surfaces": {"type": "array", "items": _SURFACE},
            "obstacles": {"type": "array", "items": _OBSTACLE},
            "contacts": {
                "type": "array",
                "minItems": 1,
                "items": {"oneOf": [_contact(k) for k in contact_types()]},
            },
            "tasks": {
                "type": ["array", "null"],
                "items": {"oneOf": [_task(k) for k in kinds]},
            },
            "costs": _COSTS,
            "options": _OPTIONS,
        },
        "required": ["robot", "contacts"],
        "additionalProperties": False,
    }


def shipped_schema_path() -> Path:
    """The schema shipped in the package (``data/problem.schema.json``, posturegen's tasks)."""
    return Path(str(importlib.resources.files("posturegen") / "data" / "problem.schema.json"))


def validate(data: Any, schema: dict[str, Any] | None = None) -> list[str]:
    """Where ``data`` (a problem file's content) breaks the schema, one line each (none: it
    fits)."""
    validator = jsonschema.Draft202012Validator(schema or problem_schema())
    out = []
    for error in sorted(validator.iter_errors(data), key=lambda e: list(e.absolute_path)):
        where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path)
        out.append(f"{where.lstrip('.') or 'problem'}: {error.message}")
    return out


def cmd_schema(args: argparse.Namespace) -> int:
    """``posturegen schema``: print the schema, or validate files against it (exit 2 when
    one does not fit, each failure one line)."""
    schema = problem_schema()
    if not args.validate:
        text = json.dumps(schema, indent=1)
        if args.out:
            Path(args.out).write_text(text + "\n")
        else:
            print(text)
        return 0
    bad = 0
    for path in args.validate:
        errors = validate(read_yaml(path), schema)
        bad += bool(errors)
        for line in errors:
            print(f"{path}: {line}", file=sys.stderr)
        if not errors:
            print(f"{path}: ok")
    return 2 if bad else 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``schema`` sub-command."""
    p = sub.add_parser("schema", help="print the problem file's JSON Schema, or validate files")
    p.add_argument("--validate", nargs="+", metavar="FILE", help="problem files to check")
    p.add_argument("-o", "--out", help="write the schema to this file")
    p.set_defaults(func=cmd_schema)
