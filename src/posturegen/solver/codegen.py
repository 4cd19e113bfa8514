"""Generated C for a program's functions, compiled once per structure and cached on disk.

IPOPT evaluates five functions of the program at every iteration: the cost f, the constraints
g, ∇f, the Jacobian ∂g/∂x and the Hessian of the Lagrangian ∇²ₓ(σ·f + λᵀg). CasADi's SX
virtual machine interprets them; their C (CasADi's code generator), compiled with the system's
C compiler, runs the same floating-point operations in the same order (no fast-math, no
contraction into fused multiply-adds), so an IPOPT run gives the same iterates to rounding.

A library is keyed by the structure's fingerprint (:mod:`posturegen.solver.fingerprint`: the
package's sources, the robot's model, each term's structure and what it reads), else by the
SHA-256 of the program's *content* (the serialized function (x, p) -> (f, g)), plus the CasADi
version, the machine and the compiler flags. Any change of a term, a robot or a contact type
gives a new key (the collision pairs held are parameters: an active set's change, or a capacity
already compiled, keeps it); the same structure in another process or a later
session finds its library in ``cache_dir()`` (``$POSTUREGEN_CACHE/solvers``, else
``~/.cache/posturegen/solvers``) and pays no compilation. Beside each library, its layout
(``KEY.layout.npz``: where each block sits in x, p and g, the bounds) and, in the library, the
program and its outputs: a structure found by its fingerprint is solved and re-checked without
declaring its symbolic program.

Modes (:attr:`posturegen.solver.problem.SolverOptions.codegen`, else ``$POSTUREGEN_CODEGEN``):

- ``auto`` (default): a structure whose library is on disk is solved with it at once; else
  its library is built before its first solve (the call waits for the compiler, once per
  structure and machine). Measured on Talos' near-body reaches never seen, a fresh process
  with an empty cache, 2 cores: the first call took 16-24 s, every later one ran generated C
  (median 59 ms); building in the background while the virtual machine solved left the
  next 15 calls at 230-710 ms each (the compiler held both cores for longer than they took);
- ``sync``: the same as ``auto`` (kept for problem files: ``options.solver.jit``);
- ``background``: the virtual machine solves while the library compiles in a background
  thread, started at the structure's first use; the next solve after the build switches to
  it (a single solve never waits for a compiler);
- ``cached``: a structure's library when the disk cache has it, else the virtual machine
  (its collision kernels in machine code once compiled: :mod:`posturegen.collision.native`);
  no program is compiled. The planner's mode (a plan meets each structure a few times): measured
  2026-12-04, ATLAS' stairs of 2 steps planned with an empty cache, 9 postures on 10
  structures, took 10.7 s on the virtual machine against 162.8 s in mode ``auto`` (159 s of
  it compiling) and 29.4 s in mode ``background`` (the compiler on the other core, the
  sources generated in the foreground); with every library on disk, 3.4 s;
- ``off``: the virtual machine only. Without a C compiler every mode is ``off``.

IPOPT's five functions are compiled at ``-Og`` (gcc 12, Talos' Hessian of the Lagrangian:
4.5× faster than the virtual machine, as fast as ``-O1`` or within 30 %, but 3-11 s to compile
instead of 14-22 s, spent in register allocation; ``-O2`` took 200 s for no gain); the two
functions IPOPT never calls in a solve but ``nlpsol`` requires (the program itself and its
gradient, for the multipliers of the parameters) at ``-O0``. The sources compile in parallel,
the largest first.

The compilers never outlive the process that started them (:mod:`posturegen._lifeline`): each
runs in its own process group, killed at exit, and by a watchdog when the process ends any
other way (SIGTERM, SIGKILL); a build that takes longer than ``COMPILE_TIMEOUT_S`` is killed
and counts as failed (the virtual machine solves on).
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from .. import _lifeline
from .._compiler import Entry, cache_root, compiler, evict_least_recent
from ..errors import InputError

CODEGEN_VERSION = 2  # 2: the outputs function in the library, the layout beside it
MODES = ("auto", "sync", "background", "cached", "off")
# the functions IPOPT calls at every iteration, and those nlpsol needs to exist
HOT_FUNCTIONS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")
COLD_FUNCTIONS = ("nlp", "nlp_grad", "outputs")
HOT_FLAGS = ("-Og", "-ffp-contract=off")
COLD_FLAGS = ("-O0",)
# least recently used libraries beyond this are deleted (1-4 MB each; `posturegen bench --jit`
# alone left 91 of them, 252 MB, against 256 MB, the bound before)
MAX_CACHE_BYTES = 1 << 30
BACKGROUND_AFTER_USES = 1  # mode background: compile once a structure is solved this often
COMPILE_TIMEOUT_S = 600.0  # a library's build (compilation and link) that takes longer fails


def cache_dir() -> Path:
    """Where compiled libraries are cached: $POSTUREGEN_CACHE/solvers, else
    ~/.cache/posturegen/solvers."""
    return cache_root() / "solvers"


def resolve_mode(option: str | None) -> str:
    """The effective mode: the option, else $POSTUREGEN_CODEGEN, else ``auto``; ``off`` without
    a C compiler."""
    env = os.environ.get("POSTUREGEN_CODEGEN")
    mode = option or env or "auto"
    if mode not in MODES:
        where = "SolverOptions.codegen" if option else "$POSTUREGEN_CODEGEN"
        raise InputError(where, f"unknown codegen mode '{mode}'", f"use one of: {', '.join(MODES)}")
    if mode != "off" and compiler() is None:
        return "off"
    return mode


def _key_hash(extra: str) -> Any:
    """A SHA-256 started with what every key covers: the code generator's version, CasADi's,
    the machine, the compiler flags, and ``extra``."""
    return hashlib.sha256(
        repr(
            (CODEGEN_VERSION, ca.__version__, platform.machine(), HOT_FLAGS, COLD_FLAGS, extra)
        ).encode()
    )


def library_key(nlp: ca.Function, extra: str = "") -> str:
    """SHA-256 (20 hex digits) of the program (x, p) -> (f, g), ``extra`` (what else its
    derivative functions depend on: posturegen.solver.problem._Program.derivative_key), the CasADi
    version, the machine and the compiler flags."""
    h = _key_hash(extra)
    h.update(nlp.serialize().encode())
    return h.hexdigest()[:20]


def structure_key(fingerprint: str) -> str:
    """The library key (20 hex digits) of a structure's fingerprint
    (:func:`posturegen.solver.fingerprint.structure_fingerprint`), the CasADi version, the
    machine and the compiler flags."""
    return _key_hash("structure " + fingerprint).hexdigest()[:20]


def library_path(key: str) -> Path:
    """The cached library of a key (it may not exist yet)."""
    return cache_dir() / f"{key}.so"


def layout_path(key: str) -> Path:
    """The layout beside the library of a key."""
    return cache_dir() / f"{key}.layout.npz"


def read_layout(key: str) -> dict[str, np.ndarray] | None:
    """The arrays saved beside the library of ``key`` (None when absent or unreadable)."""
    try:
        with np.load(layout_path(key)) as data:
            return {name: data[name] for name in data.files}
    except (OSError, ValueError):
        return None


def program_functions(key: str) -> tuple[ca.Function, ca.Function] | None:
    """The program (x, p) -> (f, g) and its outputs from the library of ``key`` (None when
    the library lacks them)."""
    path = str(library_path(key))
    try:
        return ca.external("nlp", path), ca.external("outputs", path)
    except RuntimeError:
        return None


@dataclass(frozen=True)
class BuildInfo:
    """One library build: generation and compilation wall times [s], size [bytes]."""

    key: str
    generate_s: float
    compile_s: float
    size: int
    background: bool


BUILDS: list[BuildInfo] = []  # every build of this process, in order
_LOCK = threading.Condition()
_QUEUE: list[tuple[str, Path, list[tuple[Path, bool]], float]] = []  # background jobs, FIFO
_PENDING: set[str] = set()  # keys queued or compiling
_WORKER: threading.Thread | None = None
_FAILED: set[str] = set()
_TMPDIRS: set[Path] = set()
_EXITING = False


def load(key: str, ipopt_options: dict[str, Any]) -> ca.Function | None:
    """IPOPT on the cached library of ``key`` (None when it is not built, or fails to load)."""
    path = library_path(key)
    if not path.is_file():
        return None
    try:
        solver = ca.nlpsol("posture", "ipopt", str(path), ipopt_options)
    except RuntimeError as exc:  # a truncated or foreign file: rebuild it
        warnings.warn(f"posturegen: ignoring compiled solver {path}: {exc}", stacklevel=2)
        path.unlink(missing_ok=True)
        return None
    try:
        os.utime(path)  # least recently used pruning
    except OSError:
        pass
    return solver


@dataclass(frozen=True)
class Sources:
    """What a library is generated from: the solver (IPOPT's functions), the program
    (x, p) -> (f, g), its outputs, and the layout arrays saved beside it."""

    solver: ca.Function
    nlp: ca.Function
    outputs: ca.Function
    layout: dict[str, np.ndarray]


def build(key: str, what: Sources) -> BuildInfo | None:
    """Generate, compile and cache the library of ``key`` now (waits; after a queued
    background build of it, if any); None when it was already built or the build failed."""
    wait(key)
    if key in _FAILED or library_path(key).is_file():
        return None
    t0 = time.perf_counter()
    tmp, sources = _generate(what)
    return _compile(key, tmp, sources, time.perf_counter() - t0, background=False)


def build_in_background(key: str, what: Sources) -> None:
    """Generate the sources now (CasADi, a fraction of a second) and queue their compilation
    for the background worker (one daemon thread: one build at a time, each using the cores
    in parallel); the library appears in the cache when done."""
    with _LOCK:
        if key in _PENDING or key in _FAILED or library_path(key).is_file():
            return
        _PENDING.add(key)
    t0 = time.perf_counter()
    try:
        tmp, sources = _generate(what)
    except BaseException:
        with _LOCK:
            _PENDING.discard(key)
            _LOCK.notify_all()
        raise
    global _WORKER
    with _LOCK:
        _QUEUE.append((key, tmp, sources, time.perf_counter() - t0))
        if _WORKER is None:
            _WORKER = threading.Thread(target=_work, name="posturegen-cc", daemon=True)
            _WORKER.start()


def _work() -> None:
    """The background worker: compile the queued jobs in order, then stop."""
    global _WORKER
    while True:
        with _LOCK:
            if not _QUEUE:
                _WORKER = None
                return
            key, tmp, sources, generate_s = _QUEUE.pop(0)
        try:
            _compile(key, tmp, sources, generate_s, background=True)
        finally:
            with _LOCK:
                _PENDING.discard(key)
                _LOCK.notify_all()


def pending() -> list[str]:
    """Keys whose background build is queued or running."""
    with _LOCK:
        return sorted(_PENDING)


def wait(key: str | None = None, timeout: float | None = None) -> bool:
    """Wait until the background build of ``key`` (every build when None) is done; False when
    the timeout [s] expired first."""
    with _LOCK:
        return _LOCK.wait_for(
            lambda: (key not in _PENDING) if key is not None else not _PENDING, timeout
        )


def _generate(what: Sources) -> tuple[Path, list[tuple[Path, bool]]]:
    """C sources of the library, one per function, in a fresh temporary folder next to the
    cache; each with whether it is hot (compiled optimized); the layout saved there."""
    root = cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=root))
    with _LOCK:
        _TMPDIRS.add(tmp)
    np.savez(tmp / "layout.npz", **what.layout)
    own = {"nlp": what.nlp, "outputs": what.outputs}
    sources = []
    for name in (*HOT_FUNCTIONS, *COLD_FUNCTIONS):
        fn = own[name] if name in own else what.solver.get_function(name)
        gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        gen.add(fn)
        sources.append((Path(gen.generate(str(tmp) + os.sep)), name in HOT_FUNCTIONS))
    # largest first: the Hessian alone sets the wall time
    sources.sort(key=lambda s: -s[0].stat().st_size)
    return tmp, sources


def _compile(
    key: str, tmp: Path, sources: list[tuple[Path, bool]], generate_s: float, background: bool
) -> BuildInfo | None:
    """Compile the sources in parallel (one job per core; in the background one core is left
    to the solver), link, and move the library into the cache atomically (concurrent builders
    of one key write the same bytes). A build that takes longer than COMPILE_TIMEOUT_S fails:
    its compilers are killed."""
    cc = compiler()
    t0 = time.perf_counter()
    try:
        if cc is None:
            raise RuntimeError("no C compiler")
        deadline = t0 + COMPILE_TIMEOUT_S
        jobs = max(1, min((os.cpu_count() or 1) - background, 4))
        # in the background, at a lower priority than the solves
        nice = ["nice", "-n", "10"] if background and shutil.which("nice") else []
        commands = []
        for src, hot in sources:
            flags = HOT_FLAGS if hot else COLD_FLAGS
            obj = str(src.with_suffix(".o"))
            cmd = [*nice, cc, "-c", "-fPIC", "-w", *flags, str(src), "-o", obj]
            commands.append((cmd, src.name, src.with_suffix(".log")))
        _run(commands, jobs, deadline)
        out = tmp / "lib.so"
        objects = [str(src.with_suffix(".o")) for src, _ in sources]
        _run([([cc, "-shared", *objects, "-o", str(out)], "link", tmp / "link.log")], 1, deadline)
        size = out.stat().st_size
        os.replace(tmp / "layout.npz", layout_path(key))  # first: a library has its layout
        os.replace(out, library_path(key))
        info = BuildInfo(key, generate_s, time.perf_counter() - t0, size, background)
        BUILDS.append(info)
        _prune()
        return info
    except (OSError, RuntimeError) as exc:
        if not _EXITING:  # else the compilers were stopped on purpose
            _FAILED.add(key)
            warnings.warn(
                f"posturegen: C build failed, using the virtual machine: {exc}", stacklevel=2
            )
        return None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        with _LOCK:
            _TMPDIRS.discard(tmp)


def _run(commands: list[tuple[list[str], str, Path]], jobs: int, deadline: float) -> None:
    """Run ``(command, what, log)`` jobs, ``jobs`` at a time (a free core takes the next one
    at once); raise on the first failure or at the ``deadline`` (perf_counter) [s], after
    killing the jobs still running."""
    queue = list(commands)
    running: list[tuple[subprocess.Popen, str, Path]] = []
    try:
        while queue or running:
            while queue and len(running) < jobs:
                if _EXITING:  # the process is ending: start no other compiler
                    raise RuntimeError("the process is exiting")
                cmd, what, log = queue.pop(0)
                running.append((_lifeline.spawn(cmd, log), what, log))
            done = [job for job in running if _lifeline.finished(job[0])]
            for job in done:
                running.remove(job)
                _check(*job)
            if not done:
                if time.perf_counter() > deadline:
                    raise RuntimeError(f"compilation took longer than {COMPILE_TIMEOUT_S:g} s")
                time.sleep(0.02)
    finally:
        for proc, _, _ in running:  # after a failure or the deadline: stop the other jobs
            _lifeline.kill(proc)


def _check(proc: subprocess.Popen, what: str, log: Path) -> None:
    """Raise with a finished compiler's messages when it failed."""
    if proc.returncode != 0:
        msg = log.read_text(errors="replace")[:500] if log.is_file() else ""
        raise RuntimeError(f"{what}: exit {proc.returncode}: {msg}")


def _prune() -> None:
    """Delete the least recently used libraries (by modification time, which :func:`load`
    refreshes) and their layouts beyond MAX_CACHE_BYTES in all."""

    def libraries() -> list[Entry]:
        out: list[Entry] = []
        for path in cache_dir().glob("*.so"):
            st = path.stat()
            out.append((st.st_mtime, st.st_size, functools.partial(_remove_library, path)))
        return out

    evict_least_recent(libraries, MAX_CACHE_BYTES)


def _remove_library(path: Path) -> None:
    """Delete a cached library and its layout."""
    path.unlink(missing_ok=True)
    layout_path(path.stem).unlink(missing_ok=True)


@atexit.register
def _cancel() -> None:
    """At exit: stop the compilers this process started and remove their temporary files."""
    global _EXITING
    _EXITING = True
    with _LOCK:
        tmps = list(_TMPDIRS)
        _QUEUE.clear()
    _lifeline.kill_all()
    for tmp in tmps:
        shutil.rmtree(tmp, ignore_errors=True)
