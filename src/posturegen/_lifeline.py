"""Child processes that do not outlive this Python process, however it ends.

Each child runs in a process group of its own (a compiler driver's group also holds the
compiler proper, ``cc1``, and the assembler it starts), so :func:`kill` stops all of it. The
groups are also told to a *watchdog*: one small Python process, started at the first
:func:`spawn` in a session of its own, that reads ``+PGID`` / ``-PGID`` lines from a pipe whose
write end only this process holds (close-on-exec: the children do not inherit it). When this
process ends in any way (a normal exit, SIGTERM's default action, SIGKILL, a crash) the kernel
closes the pipe; the watchdog reads end-of-file and kills every group still listed, then
exits. A group is unlisted before its leader is reaped, so the watchdog never kills a group
whose id the kernel may have given to someone else."""

from __future__ import annotations

import atexit
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

_WATCHDOG_SOURCE = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGHUP, signal.SIG_IGN)
groups = set()
for line in sys.stdin:
    if line[:1] in "+-" and line[1:].strip().isdigit():
        (groups.add if line[0] == "+" else groups.discard)(int(line[1:]))
for pgid in groups:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except OSError:
        pass
"""

_LOCK = threading.Lock()
_CHILDREN: set[subprocess.Popen] = set()
_watchdog: subprocess.Popen | None = None
_no_watchdog = False  # it could not be started: the children are still killed at exit


def _tell(line: str) -> None:
    """Send a line to the watchdog (started on first use); ignored when it is gone."""
    global _watchdog, _no_watchdog
    if _watchdog is None and not _no_watchdog:
        try:
            _watchdog = subprocess.Popen(
                [sys.executable, "-I", "-S", "-c", _WATCHDOG_SOURCE],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,  # neither a terminal's ^C nor a signal to our group
            )
        except OSError:
            _no_watchdog = True
    pipe = _watchdog.stdin if _watchdog is not None else None
    if pipe is None:
        return
    try:
        pipe.write(line.encode() + b"\n")
        pipe.flush()
    except (OSError, ValueError):  # the watchdog is gone
        pass


def spawn(cmd: list[str], log: Path) -> subprocess.Popen:
    """Start ``cmd`` in a new process group, its stdout discarded, its stderr in ``log``."""
    with _LOCK:
        with open(log, "wb") as err:
            proc = subprocess.Popen(
                cmd, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True
            )
        _CHILDREN.add(proc)
        _tell(f"+{proc.pid}")
    return proc


def _forget(proc: subprocess.Popen) -> None:
    with _LOCK:
        if proc in _CHILDREN:
            _CHILDREN.discard(proc)
            _tell(f"-{proc.pid}")


def finished(proc: subprocess.Popen) -> bool:
    """Whether a child of :func:`spawn` has exited (then it is unlisted and reaped: its
    ``returncode`` is set)."""
    if proc.returncode is not None:
        return True
    try:  # exited? without reaping it, so that its group id stays ours until unlisted
        info = os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:  # reaped elsewhere
        info = True
    if info is None:
        return False
    _forget(proc)
    proc.wait()
    return True


def kill(proc: subprocess.Popen) -> None:
    """Stop a child of :func:`spawn` and everything in its process group, and reap it (after
    unlisting it, as :func:`finished` does)."""
    if proc.returncode is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        try:
            os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOWAIT)  # dead, not yet reaped
        except ChildProcessError:
            pass
    _forget(proc)
    proc.wait()


def kill_all() -> None:
    """Stop every child of :func:`spawn` still running."""
    with _LOCK:
        procs = list(_CHILDREN)
    for proc in procs:
        kill(proc)


def running() -> list[int]:
    """Process group ids of the children still listed."""
    with _LOCK:
        return sorted(p.pid for p in _CHILDREN)


@atexit.register
def _close() -> None:
    """At a normal exit: stop the children, then let the watchdog go (end of its input)."""
    global _watchdog
    kill_all()
    if _watchdog is not None:
        if _watchdog.stdin is not None:
            _watchdog.stdin.close()
        try:
            _watchdog.wait(timeout=5)
        except subprocess.TimeoutExpired:
            _watchdog.kill()
        _watchdog = None
