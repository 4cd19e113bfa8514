"""The one registry of the package's extension points (contact types, tasks): classes by their
``kind``, the name a problem file gives in ``type``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar

from .errors import InputError
from .hints import with_hint

C = TypeVar("C", bound=type)


class Registry(Generic[C]):
    """Classes by ``kind``, in registration order; ``what`` names them in errors."""

    def __init__(self, what: str) -> None:
        self.what = what
        self._by_kind: dict[str, C] = {}

    def register(self, cls: C, check: Callable[[C], None] | None = None) -> C:
        """Register ``cls`` under its ``kind`` (``check``: the kind's own rules, run before it
        is stored). The same class defined again (a script or notebook cell run twice)
        replaces itself; another class under a known kind is an error."""
        kind = getattr(cls, "kind", None)
        if not isinstance(kind, str) or not kind:
            raise InputError(f"{cls.__name__}.kind", "missing", f"set kind = 'my_{self.what}'")
        known = self._by_kind.get(kind)
        if known is not None and (known.__module__, known.__qualname__) != (
            cls.__module__,
            cls.__qualname__,
        ):
            raise InputError(
                f"{cls.__name__}.kind",
                f"{self.what} type {kind!r} is registered already (by {known.__qualname__})",
                "choose another kind",
            )
        if check is not None:
            check(cls)
        self._by_kind[kind] = cls
        return cls

    def types(self) -> dict[str, C]:
        """The registered classes by kind, in registration order."""
        return dict(self._by_kind)

    def lookup(self, kind: Any, fld: str) -> C:
        """The class of ``kind`` (a file's ``type``, at field ``fld``), or the one-line error
        naming the close kinds."""
        if not isinstance(kind, str) or kind not in self._by_kind:
            names = list(self._by_kind)
            raise InputError(
                fld,
                "missing" if kind is None else f"unknown {self.what} type {kind!r}",
                with_hint(str(kind), names, f"use one of: {', '.join(names)}"),
            )
        return self._by_kind[kind]
