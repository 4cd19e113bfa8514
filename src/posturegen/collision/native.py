"""The collision rows' kernels in machine code, compiled once per machine and kept on disk.

A program that runs on CasADi's virtual machine (codegen modes ``cached`` and ``background``,
:mod:`posturegen.solver.codegen`: the planner's, where nearly every posture is a structure
never compiled) spends most of an iteration in its collision rows: on Talos' touch of step 3
(55 variables, 50 collision rows of 128) the Hessian of the Lagrangian took 2.4 ms a call
against 0.3 ms without the rows. The rows' work is done by a few SX kernels
(:mod:`~.self_blocks`, :mod:`~.env_slots`) whose shapes depend on the robot, not on the
structure nor (self rows) on the capacity. Compiled (CasADi's ``jit``, the library kept beside
the saved function, so that a later process opens it in milliseconds) the same Hessian took
0.83 ms, and the same 521 iterations gave the same posture bit for bit: the C runs the virtual
machine's operations in the same order (no fast-math, no contraction into fused
multiply-adds).

A kernel is keyed by the SHA-256 of its serialized function, CasADi's version, the machine and
the flags, and kept in ``$POSTUREGEN_CACHE/kernels`` (else ``~/.cache/posturegen/kernels``),
the least recently used deleted beyond MAX_CACHE_BYTES. The kernels a program needs and that
the disk does not hold are compiled by a builder process of their own (:func:`ready`), on the
other core, while the programs declared meanwhile run them on the virtual machine: Talos' set
took 4.1 s at ``-O1`` (``-O0``: 2.0 s, but the Hessian at 1.4 ms), a wait no plan should
make. The workers of a plan or a batch each start a builder for the same kernels: a builder
compiles a kernel under a claim (a file made atomically) and leaves those another one holds to
it (Talos' 4-stair plan from an empty cache on two workers: 13.4 s, 16.0 s when both
builders compiled every kernel). Without a C compiler, or when a build fails, the kernels stay
on the virtual machine.
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import casadi as ca

from .. import _lifeline
from .._cache import BoundedCache, Ref
from .._compiler import Entry, cache_root, compiler, evict_least_recent

FLAGS = ("-O1", "-ffp-contract=off")
MAX_CACHE_BYTES = 256 << 20  # a robot's set is 2-5 MB
SAVED = "kernel.casadi"  # in each kernel's folder, beside its library
# a builder compiles a kernel under a claim (kernel_dir()/.claim-DIGEST): another builder waits
# for it (polling every CLAIM_POLL [s]) instead of compiling it too; a claim of another host
# older than CLAIM_STALE [s] is taken as left by a builder that died
CLAIM_POLL = 0.1
CLAIM_STALE = 600.0
_NATIVE: BoundedCache[ca.Function] = BoundedCache("native kernels", 64)
_DIGESTS: BoundedCache[str] = BoundedCache("kernel digests", 64)
_LOCK = threading.Lock()
_BUILDERS: dict[str, subprocess.Popen] = {}  # digest -> the builder process making it
_FAILED: set[str] = set()
_finished = 0  # builder processes done in this process


def kernel_dir() -> Path:
    """Where compiled kernels are kept."""
    return cache_root() / "kernels"


def ready(kernels: list[ca.Function]) -> bool:
    """Whether every kernel's machine code is at hand (in this process, else loaded from the
    disk); when not, the missing ones are sent to a builder process (once) and False."""
    missing = []
    for kernel in kernels:
        digest = digest_of(kernel)
        if _NATIVE.get(digest) is None:
            loaded = _from_disk(kernel.name(), digest)
            if loaded is None:
                missing.append((digest, kernel))
            else:
                _NATIVE.put(digest, loaded)
    if not missing:
        return True
    _build_in_background(missing)
    return False


def epoch() -> int:
    """How many builder processes have finished in this process: a program declared while its
    kernels were being built is declared again once this has changed."""
    with _LOCK:
        _reap()
        return _finished


def _reap() -> set[str]:
    """The digests whose builder has finished, now forgotten (under _LOCK)."""
    global _finished
    done = {d for d, proc in _BUILDERS.items() if _lifeline.finished(proc)}
    _finished += len({id(_BUILDERS[d]) for d in done})
    for digest in done:
        del _BUILDERS[digest]
    return done


def have(kernels: list[ca.Function]) -> bool:
    """Whether :func:`ready` found every kernel's machine code."""
    return all(_NATIVE.get(digest_of(k)) is not None for k in kernels)


def native(kernel: ca.Function) -> ca.Function:
    """The machine code of ``kernel`` that :func:`ready` found; ``kernel`` itself otherwise.
    Its derivatives and its generated C are those of ``kernel``."""
    return _NATIVE.get(digest_of(kernel)) or kernel


def digest_of(kernel: ca.Function) -> str:
    """The kernel's key: SHA-256 of its serialized function, CasADi's version, the machine and
    the flags (20 hex digits)."""

    def make() -> str:
        h = hashlib.sha256(repr((ca.__version__, platform.machine(), FLAGS)).encode())
        h.update(kernel.serialize().encode())
        return h.hexdigest()[:20]

    return _DIGESTS.get_or_make(Ref(kernel), make)


def wait(timeout: float | None = None) -> bool:
    """Wait until the builder processes are done; False when ``timeout`` [s] ran out first."""
    deadline = None if timeout is None else time.monotonic() + timeout
    while True:
        with _LOCK:
            running = [p for p in set(_BUILDERS.values()) if not _lifeline.finished(p)]
        if not running:
            return True
        if deadline is not None and time.monotonic() > deadline:
            return False
        time.sleep(0.05)


def _saved(name: str, digest: str) -> list[Path]:
    """The saved functions of the finished builds of kernel ``name`` of ``digest``."""
    return sorted(kernel_dir().glob(f"{name}-{digest}-*/{SAVED}"))


def _from_disk(name: str, digest: str) -> ca.Function | None:
    """The compiled kernel of ``digest`` from its folder, else None."""
    for path in _saved(name, digest):
        try:
            loaded = ca.Function.load(str(path))
        except RuntimeError:  # unreadable (its library moved, another CasADi): built again
            shutil.rmtree(path.parent, ignore_errors=True)
            continue
        os.utime(path.parent)  # recently used
        return loaded
    return None


def _build_in_background(missing: list[tuple[str, ca.Function]]) -> None:
    """Start one builder process for the kernels not yet sent to one (nor failed)."""
    cc = compiler()
    wanted = {d for d, _ in missing}
    with _LOCK:
        _FAILED.update(_reap() & wanted)  # their builder is done, yet they are not on the disk
        todo = [(d, k) for d, k in missing if d not in _BUILDERS and d not in _FAILED]
        if cc is None or not todo:
            return
        root = kernel_dir()
        root.mkdir(parents=True, exist_ok=True)
        jobs = Path(tempfile.mkdtemp(prefix=".jobs-", dir=root))
        largest_first = sorted(todo, key=lambda t: -t[1].n_nodes())
        for k, (digest, kernel) in enumerate(largest_first):
            kernel.save(str(jobs / f"{k:02d}-{digest}.casadi"))
        cmd = ["nice", "-n", "5"] if shutil.which("nice") else []
        cmd += [sys.executable, "-m", __name__, str(jobs), cc]
        # stopped at exit with every child of _lifeline (a half-made folder has no SAVED)
        proc = _lifeline.spawn(cmd, jobs / "builder.log")
        for digest, _ in todo:
            _BUILDERS[digest] = proc


def build(kernel: ca.Function, digest: str, cc: str) -> Path:
    """Compile ``kernel`` with ``cc`` into a folder of its own in the cache: its library and
    the function that runs it (saved last: a folder without it is a build in progress or a
    failed one; :func:`_main` keeps two builders from making the same). Returns the saved
    function."""
    root = kernel_dir()
    root.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix=f"{kernel.name()}-{digest}-", dir=root))
    try:
        args = kernel.sx_in()
        options = {
            "jit": True,
            "compiler": "shell",
            "jit_serialize": "link",  # the saved function opens the library where it is
            "jit_name": kernel.name(),
            "jit_temp_suffix": False,
            "jit_cleanup": False,
            "jit_options": {
                "compiler": cc,
                "flags": list(FLAGS),
                "directory": str(folder) + os.sep,
                "cleanup": False,
                "verbose": False,
            },
        }
        compiled = ca.Function(kernel.name(), args, kernel.call(args), options)
        for source in (*folder.glob("*.c"), *folder.glob("*.o")):
            source.unlink()
        compiled.save(str(folder / f"{SAVED}.partial"))
        os.replace(folder / f"{SAVED}.partial", folder / SAVED)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    _prune()
    return folder / SAVED


def _prune() -> None:
    """Delete the least recently used kernels (their folders, by modification time, which
    :func:`_from_disk` refreshes) beyond MAX_CACHE_BYTES in all."""

    def folders() -> list[Entry]:
        return [
            (
                folder.stat().st_mtime,
                sum(f.stat().st_size for f in folder.iterdir()),
                functools.partial(shutil.rmtree, folder, ignore_errors=True),
            )
            for folder in kernel_dir().iterdir()
            if (folder / SAVED).is_file()
        ]

    evict_least_recent(folders, MAX_CACHE_BYTES)


def _claim_path(digest: str) -> Path:
    return kernel_dir() / f".claim-{digest}"


def _claim(digest: str) -> Path | None:
    """The claim file of ``digest`` when this builder now holds it (created atomically; it
    names this host and process); None when another builder holds it."""
    path = _claim_path(digest)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        return None
    with os.fdopen(fd, "w") as f:
        f.write(f"{platform.node()} {os.getpid()}")
    return path


def _held(digest: str) -> bool:
    """Whether a live builder holds the claim of ``digest``: one of this host whose process
    runs, or one of another host (a shared cache) younger than CLAIM_STALE [s]. A stale claim
    is removed."""
    path = _claim_path(digest)
    try:
        host, pid = path.read_text().split()
        age = time.time() - path.stat().st_mtime
    except (OSError, ValueError):
        return path.exists()  # being written, or gone
    if host == platform.node():
        try:
            os.kill(int(pid), 0)
            return True
        except ProcessLookupError:
            pass
        except PermissionError:
            return True
    elif age < CLAIM_STALE:
        return True
    path.unlink(missing_ok=True)
    return False


def _main(jobs: Path, cc: str) -> None:
    """The builder process: compile each job of ``jobs`` not on the disk yet, largest first,
    one at a time under its claim; a job another builder holds (the workers of a plan or a
    batch, each with a builder of its own, need the same kernels) is left to it, and waited
    for at the end (built here if that builder ended without it). Then remove the folder."""
    try:
        pending = [
            (job.stem.split("-", 1)[1], ca.Function.load(str(job)))
            for job in sorted(jobs.glob("*.casadi"))
        ]
        while pending:
            waiting = []
            for digest, kernel in pending:
                if _saved(kernel.name(), digest):
                    continue  # checked just before its claim: another builder may have made it
                claim = _claim(digest)
                if claim is None:
                    waiting.append((digest, kernel))
                    continue
                try:
                    if not _saved(kernel.name(), digest):  # made between the check and the claim
                        build(kernel, digest, cc)
                finally:
                    claim.unlink(missing_ok=True)
            pending = _unbuilt(waiting)
            while pending and all(_held(digest) for digest, _ in pending):
                time.sleep(CLAIM_POLL)
                pending = _unbuilt(pending)
    finally:
        shutil.rmtree(jobs, ignore_errors=True)


def _unbuilt(kernels: list[tuple[str, ca.Function]]) -> list[tuple[str, ca.Function]]:
    """The (digest, kernel) pairs of ``kernels`` whose build is not on the disk."""
    return [(d, k) for d, k in kernels if not _saved(k.name(), d)]


if __name__ == "__main__":
    _main(Path(sys.argv[1]), sys.argv[2])
