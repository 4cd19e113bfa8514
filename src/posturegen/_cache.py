"""The one bounded cache of the package: every module-level cache is a :class:`BoundedCache`
(least recently used entry evicted beyond its bound), and :func:`clear_caches` empties them all.

A cache holds what it keys on: a key that names an object by identity wraps it in :class:`Ref`,
which keeps the object alive as long as the entry (``id()`` of an object the cache does not hold
can be reused by a new object after the first is freed, and hit a stale entry)."""

from __future__ import annotations

import collections
import functools
import threading
from collections.abc import Callable, Hashable
from typing import Any, Generic, TypeVar

V = TypeVar("V")

_ALL: list[BoundedCache[Any]] = []


class Ref:
    """An object as a key by identity: equal only to a Ref of the same object, hashed by its id,
    and holding the object (so that its id is not reused while the key lives)."""

    __slots__ = ("obj",)

    def __init__(self, obj: object) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Ref) and other.obj is self.obj

    def __repr__(self) -> str:
        return f"Ref({type(self.obj).__name__} at {id(self.obj):#x})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (Ref, (self.obj,))


class BoundedCache(Generic[V]):
    """A mapping of at most ``size`` entries, least recently used evicted first; thread-safe
    (one lock per cache); registered for :func:`clear_caches` unless ``register`` is False
    (a thread's own cache)."""

    def __init__(self, name: str, size: int, register: bool = True) -> None:
        if size < 1:
            raise ValueError(f"cache '{name}': size must be >= 1")
        self.name, self.size = name, size
        self._data: collections.OrderedDict[Hashable, V] = collections.OrderedDict()
        self._lock = threading.RLock()
        if register:
            _ALL.append(self)

    def get(self, key: Hashable, default: V | None = None) -> V | None:
        """The value of ``key`` (now the most recently used), else ``default``."""
        with self._lock:
            if key not in self._data:
                return default
            self._data.move_to_end(key)
            return self._data[key]

    def put(self, key: Hashable, value: V) -> V:
        """Store ``value`` under ``key``, evicting the least recently used beyond the bound."""
        with self._lock:
            self._data[key] = value
            self._data.move_to_end(key)
            while len(self._data) > self.size:
                self._data.popitem(last=False)
        return value

    def get_or_make(self, key: Hashable, make: Callable[[], V]) -> V:
        """The value of ``key``, made by ``make()`` and stored when absent (``make`` runs
        outside the lock: two threads may both make it, the last one stored wins)."""
        with self._lock:
            if key in self._data:
                self._data.move_to_end(key)
                return self._data[key]
        return self.put(key, make())

    def __getitem__(self, key: Hashable) -> V:
        with self._lock:
            value = self._data[key]
            self._data.move_to_end(key)
            return value

    def __setitem__(self, key: Hashable, value: V) -> None:
        self.put(key, value)

    def __contains__(self, key: Hashable) -> bool:
        with self._lock:
            return key in self._data

    def __len__(self) -> int:
        return len(self._data)

    def clear(self) -> None:
        """Drop every entry."""
        with self._lock:
            self._data.clear()


def memoize(name: str, size: int) -> Callable[[Callable[..., V]], Callable[..., V]]:
    """A function's results cached by its (hashable) arguments in a :class:`BoundedCache` of
    ``size`` entries; ``fn.cache`` is the cache, ``fn.cache_clear()`` empties it."""

    def wrap(fn: Callable[..., V]) -> Callable[..., V]:
        cache: BoundedCache[V] = BoundedCache(name, size)

        @functools.wraps(fn)
        def cached(*args: Hashable, **kwargs: Hashable) -> V:
            key = (args, tuple(sorted(kwargs.items())))
            return cache.get_or_make(key, lambda: fn(*args, **kwargs))

        cached.cache = cache  # type: ignore[attr-defined]
        cached.cache_clear = cache.clear  # type: ignore[attr-defined]
        return cached

    return wrap


def clear_caches() -> None:
    """Empty every in-process cache of the package (compiled programs, learned active sets,
    robots, fitted ellipses...; the disk caches stay)."""
    for cache in _ALL:
        cache.clear()
