"""Where the package keeps what it compiles, and the C compiler it compiles with."""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

from ._cache import BoundedCache

# an entry of a disk cache: (its last use as a modification time [s], its size [bytes], what
# removes it)
Entry = tuple[float, int, Callable[[], None]]


def cache_root() -> Path:
    """The package's disk cache: $POSTUREGEN_CACHE, else ~/.cache/posturegen."""
    return Path(os.environ.get("POSTUREGEN_CACHE") or Path.home() / ".cache" / "posturegen")


# the compiler found for ($CC, $PATH): every solve asks which codegen mode it runs in, and a
# PATH search is 70 µs of a 2.6 ms call
_FOUND: BoundedCache[str | None] = BoundedCache("C compilers found", 8)


def compiler() -> str | None:
    """The C compiler: $CC, else gcc, else cc (None when none is on the PATH)."""
    cc, path = os.environ.get("CC"), os.environ.get("PATH")
    return _FOUND.get_or_make((cc, path), lambda: _search(cc, path))


def _search(cc: str | None, path: str | None) -> str | None:
    """The first of ``cc``, gcc and cc on ``path`` (None: none of them)."""
    for name in (cc, "gcc", "cc"):
        if name and (found := shutil.which(name, path=path)):
            return found
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


# the flags of the package's own C kernels: the same floating-point operations in the same
# order as written (no fused multiply-adds, no fast-math)
KERNEL_FLAGS = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")


def kernel_path(name: str, source: str) -> Path:
    """Where this machine keeps the kernel ``name`` compiled from ``source``: in
    ``cache_root()/kernels``, keyed by the source's and the machine's digest."""
    digest = hashlib.sha256(
        f"{source}|{platform.machine()}|{platform.system()}".encode()
    ).hexdigest()[:16]
    return cache_root() / "kernels" / f"{name}-{digest}.so"


def kernel_library(name: str, source: str) -> ctypes.CDLL | None:
    """The kernel ``name`` compiled from the C ``source`` (KERNEL_FLAGS) at its first use on
    this machine and loaded; None without a C compiler or when the build or the load fails.
    The build is written aside and moved in place at once (another process may be at it)."""
    cc = compiler()
    if cc is None:
        return None
    path = kernel_path(name, source)
    if not path.exists():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
                src = Path(tmp) / f"{name}.c"
                src.write_text(source)
                out = Path(tmp) / path.name
                cmd = [cc, *KERNEL_FLAGS, str(src), "-o", str(out), "-lm"]
                subprocess.run(cmd, check=True, capture_output=True, timeout=120)
                os.replace(out, path)
        except (OSError, subprocess.SubprocessError):
            return None
    try:
        return ctypes.CDLL(str(path))
    except OSError:
        return None


def capsule_pointer(capsule: object) -> int:
    """The C pointer a PyCapsule holds (a function or an object another extension exports to
    C: CasADi's FunctionBuffer, SciPy's LAPACK), read under the capsule's own name."""
    api = ctypes.pythonapi
    api.PyCapsule_GetName.restype = ctypes.c_char_p
    api.PyCapsule_GetName.argtypes = [ctypes.py_object]
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    return int(api.PyCapsule_GetPointer(capsule, api.PyCapsule_GetName(capsule)))
