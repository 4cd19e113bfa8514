"""Where the package keeps what it compiles, and the C compiler it compiles with."""

from __future__ import annotations

import os
import shutil
from pathlib import Path


def cache_root() -> Path:
    """The package's disk cache: $POSTUREGEN_CACHE, else ~/.cache/posturegen."""
    return Path(os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen")


def compiler() -> str | None:
    """The C compiler: $CC, else gcc, else cc (None when none is on the PATH)."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        if name and (path := shutil.which(name)):
            return path
    return None
