"""The problems of ``posturegen batch PROBLEMS...``: files, folders of them, or ``-`` for a
stream of JSON lines (one problem dict a line) on stdin."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

from ..errors import InputError
from .jobs import Unreadable

PROBLEM_SUFFIXES = (".yaml", ".yml", ".json")


def read_sources(sources: list[str], stdin: TextIO) -> list[Any]:
    """The inputs in order: a file's path, a folder's problem files (sorted by name, not
    recursive), stdin's problem dicts. A missing path or a folder without problem files is an
    InputError (nothing runs); a stdin line that is not a JSON object becomes an
    :class:`Unreadable` item (its problem fails, the others run)."""
    items: list[Any] = []
    for source in sources:
        if source == "-":
            items.extend(_json_lines(stdin))
            continue
        path = Path(source)
        if path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix in PROBLEM_SUFFIXES)
            if not files:
                raise InputError(
                    source,
                    "the folder holds no problem file",
                    f"put problem files ({', '.join(PROBLEM_SUFFIXES)}) in it",
                )
            items.extend(files)
        elif path.is_file():
            items.append(path)
        else:
            raise InputError(source, "no such file or folder", "give problem files or folders")
    if not items:
        raise InputError("PROBLEMS", "no problem given", "give files, folders or - for stdin")
    return items


def _json_lines(stream: TextIO) -> Iterator[Any]:
    """Problem dicts, one JSON object a line (blank lines skipped); each is named
    ``stdin-LINE`` unless it has a ``name``."""
    for lineno, line in enumerate(stream, start=1):
        if not line.strip():
            continue
        name = f"stdin-{lineno:05d}"
        try:
            data = json.loads(line)
        except json.JSONDecodeError as exc:
            where = f"stdin line {lineno}"
            yield Unreadable(name, f"{where}: invalid JSON ({exc.msg}, column {exc.colno})")
            continue
        if not isinstance(data, dict):
            kind = type(data).__name__
            fix = "write one problem object a line"
            yield Unreadable(name, f"stdin line {lineno}: a JSON {kind}, not an object ({fix})")
            continue
        data.setdefault("name", name)
        yield data
