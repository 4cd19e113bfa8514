"""The sequence file: its schema, its one writer (:func:`write_sequence`: the climbs' index and
the viewer's inputs) and its reader (:func:`load_sequence`).

A *sequence file* (JSON, ``"schema": "posturegen.sequence/1"``) lists the stances of a climb::

    {"schema": "posturegen.sequence/1",
     "stages": [{"name": "1: left foot on rung 2", "posture": "stage-01.json"},
                {"name": "2: right hand released", "posture": "stage-02.json"}]}

``stages[i].posture`` is a posture file path, relative to the sequence file's folder (or
absolute); ``stages[i].name`` is the stance's label; other keys are kept and ignored. Every
stage must use the same robot. :func:`write_sequence` writes one.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..errors import InputError
from .posture_file import load_posture_any
from .posture_file import read_json as read_json_file

SEQUENCE_SCHEMA = "posturegen.sequence/1"


def read_json(path: str | Path) -> dict[str, Any]:
    """A JSON object from a file, or an InputError naming the file."""
    data = read_json_file(path, "give a posture or sequence file", "give a JSON file")
    if not isinstance(data, dict):
        raise InputError(str(path), "not a JSON object", "give a posture or sequence file")
    return data


def is_sequence(data: dict[str, Any]) -> bool:
    """Whether a JSON object is a sequence file (its schema, or a ``stages`` list)."""
    return data.get("schema") == SEQUENCE_SCHEMA or isinstance(data.get("stages"), list)


def load_sequence(path: str | Path) -> list[tuple[str, dict[str, Any], Path]]:
    """The stances of a sequence file: ``(name, posture dict, posture path)`` each."""
    path = Path(path)
    data = read_json(path)
    stages = data.get("stages")
    if not isinstance(stages, list) or not stages:
        raise InputError(f"{path}: stages", "missing or empty", "list the stances' posture files")
    out = []
    for i, stage in enumerate(stages):
        where = f"{path}: stages[{i}]"
        if not isinstance(stage, dict) or not isinstance(stage.get("posture"), str):
            raise InputError(where, "needs a 'posture' file name", 'write {"posture": "a.json"}')
        file = Path(stage["posture"])
        if not file.is_absolute():
            file = path.parent / file
        name = str(stage.get("name", file.stem))
        out.append((name, load_posture_any(file), file))
    urdfs = {str(p["robot"].get("urdf")) for _, p, _ in out}
    if len(urdfs) > 1:
        raise InputError(f"{path}: stages", "the stances use different robots", "one robot")
    return out


def write_sequence(path: str | Path, stages: Sequence[dict[str, Any]], **extra: Any) -> Path:
    """Write a sequence file: ``stages`` are dicts with ``posture`` (a path) and ``name``;
    posture paths are stored relative to the sequence file's folder when they are inside it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, stage in enumerate(stages):
        if "posture" not in stage:
            raise InputError(f"stages[{i}].posture", "missing", "give the posture file path")
        file = Path(stage["posture"])
        try:
            rel = str(file.resolve().relative_to(path.parent.resolve()))
        except ValueError:
            rel = str(file.resolve())
        rows.append({**stage, "name": str(stage.get("name", file.stem)), "posture": rel})
    path.write_text(json.dumps({"schema": SEQUENCE_SCHEMA, **extra, "stages": rows}, indent=1))
    return path
