"""Where the package keeps what it compiles, and the C compiler it compiles with."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

# an entry of a disk cache: (its last use as a modification time [s], its size [bytes], what
# removes it)
Entry = tuple[float, int, Callable[[], None]]


def cache_root() -> Path:
    """The package's disk cache: $POSTUREGEN_CACHE, else ~/.cache/posturegen."""
    return Path(os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen")


def compiler() -> str | None:
    """The C compiler: $CC, else gcc, else cc (None when none is on the PATH)."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        if name and (path := shutil.which(name)):
            return path
    return None


def evict_least_recent(entries: Callable[[], Iterable[Entry]], max_bytes: int) -> None:
    """Remove the least recently used ``entries()`` beyond ``max_bytes`` in all (the most
    recent kept first); a file-system error ends the pruning (another process may be at it)."""
    try:
        total = 0
        for _used, size, remove in sorted(entries(), key=lambda e: -e[0]):
            total += size
            if total > max_bytes:
                remove()
    except OSError:
        pass
