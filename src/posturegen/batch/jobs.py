"""What travels to a worker and back: a :class:`Job` per problem, a :class:`BatchItem` per
answer.

A Job carries the problem as its problem-file dict (cheap to send, rebuilt by the worker with
``problem_from_dict``), or as a :class:`~posturegen.solver.problem.Problem` pickled with its robot
*by
name*: the worker's ``load_bundled(name)`` gives its own cached robot, so that the structure
keys (which hold ``id(robot.model)``) match and the worker's solvers are reused from one problem
to the next. A Problem built on a robot loaded from a URDF cannot travel (its patch file is not
recorded): pass its problem dict or file instead.

A BatchItem carries the frozen :class:`~posturegen.solver.solve.Result` (it pickles: about 8 kB for
Talos), or a :class:`BatchError` when the problem gave no Result at all.
"""

from __future__ import annotations

import copyreg
import dataclasses
import io
import os
import pickle
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.problem_file import read_yaml
from ..model.geometry import ConvexPolygon
from ..model.robot import Robot, load_bundled
from ..solver.problem import Problem
from ..solver.solve import Result

# what BatchError.status says
INPUT_ERROR, ERROR, CRASHED = "input error", "error", "worker crashed"


@dataclass(frozen=True)
class BatchError:
    """A problem that gave no Result: an input that cannot be read or built (``input
    error``), an exception while solving (``error``), or a worker process that died while
    solving it (``worker crashed``). ``success`` is False, as for a failed Result."""

    name: str
    status: str
    message: str  # one line

    @property
    def success(self) -> bool:
        """Always False: no posture."""
        return False

    @property
    def diagnosis(self) -> str:
        """The message (a Result's diagnosis says why no posture was found)."""
        return self.message


@dataclass(frozen=True)
class Job:
    """One problem of a batch: ``problem`` is a problem-file dict (relative robot paths from
    ``base_dir``) or a pickled Problem (bytes), or None and ``path`` a problem file that the
    worker reads (see :func:`read_file`); ``error`` set: the input could not be read and the
    worker answers with it."""

    index: int  # position in the input
    name: str  # stem of the posture file
    problem: Mapping[str, Any] | bytes | None
    base_dir: str | None = None
    error: str = ""
    path: str | None = None  # absolute


@dataclass(frozen=True)
class BatchItem:
    """The answer to one Job: ``call_time_s`` is the whole call in the worker (the problem
    built, solved, re-checked, and diagnosed when asked) [s], ``cpu_time_s`` the worker's CPU
    time in it [s] (below the call's when the machine's cores are busy elsewhere); ``worker``
    is ``host:pid``; ``warnings`` are the warnings it raised, (category, message)."""

    index: int
    name: str
    result: Result | BatchError
    call_time_s: float
    worker: str
    warnings: tuple[tuple[type[Warning], str], ...] = ()
    cpu_time_s: float = 0.0


@dataclass(frozen=True)
class Unreadable:
    """An input that could not be read (a stdin line that is not JSON): its item fails with
    ``message``, the batch goes on."""

    name: str
    message: str


class _Unshippable(Exception):
    """A Problem whose robot cannot be named to a worker."""


def _robot_by_name(robot: Robot) -> tuple[Any, tuple[str]]:
    """Pickle a bundled robot as ``load_bundled(name)``: the worker's own cached copy."""
    try:
        bundled = load_bundled(robot.name) is robot
    except InputError:
        bundled = False
    if not bundled:
        raise _Unshippable(robot.name)
    return load_bundled, (robot.name,)


def _polygon(polygon: ConvexPolygon) -> tuple[Any, tuple[Any]]:
    """Pickle a polygon as its vertices (it is immutable: no state to set)."""
    return ConvexPolygon, (polygon.vertices,)


class _ProblemPickler(pickle.Pickler):
    dispatch_table = {
        **copyreg.dispatch_table,
        Robot: _robot_by_name,
        ConvexPolygon: _polygon,
    }


def pack_problem(problem: Problem) -> bytes:
    """A Problem as bytes for a worker (its robot by name)."""
    buffer = io.BytesIO()
    _ProblemPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(problem)
    return buffer.getvalue()


def _unique(names: list[str]) -> list[str]:
    """Names made unique by a suffix (``a``, ``a-2``, ``a-3``: the first free one); ``batch``
    (the index file's stem) is taken too."""
    taken = {"batch"}
    out = []
    for name in names:
        candidate, k = name, 1
        while candidate in taken:
            k += 1
            candidate = f"{name}-{k}"
        taken.add(candidate)
        out.append(candidate)
    return out


def _job(index: int, item: Any) -> Job:
    """The Job of one input: a Problem, a problem dict, or a problem file's path."""
    if isinstance(item, Problem):
        name = f"problem-{index:04d}"
        try:
            return Job(index, name, pack_problem(item))
        except _Unshippable as exc:
            fix = "pass its problem dict or file: a robot loaded from a URDF travels by its file"
            return Job(index, name, None, error=_input_error(index, exc, fix))
        except (pickle.PicklingError, TypeError, AttributeError) as exc:  # a term of the user's
            text = f"problems[{index}]: cannot be sent to a worker ({type(exc).__name__}: {exc})"
            return Job(index, name, None, error=text)
    if isinstance(item, Mapping):
        name = item.get("name")
        stem = name if isinstance(name, str) and name else f"problem-{index:04d}"
        return Job(index, _safe(stem), item, base_dir=os.getcwd())
    if isinstance(item, str | Path):
        path = Path(item)
        return Job(index, _safe(path.stem), None, path=str(path.resolve()))
    if isinstance(item, Unreadable):
        return Job(index, _safe(item.name), None, error=item.message)
    kind = type(item).__name__
    fix = "give a Problem, a problem dict or the path of a problem file"
    return Job(index, f"problem-{index:04d}", None, error=f"problems[{index}]: a {kind} ({fix})")


def _input_error(index: int, exc: Exception, fix: str) -> str:
    return f"problems[{index}]: robot '{exc}' is not a bundled robot ({fix})"


def _safe(stem: str) -> str:
    """A file stem without path separators or leading dots."""
    cleaned = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem).lstrip(".")
    return cleaned or "problem"


def read_file(job: Job) -> Job:
    """The Job with its file read (its problem dict, or the read's error). A local worker
    reads its own files (YAML: 1.8 ms for the demo's, in parallel); a job for another machine
    is read before it leaves (posturegen.batch.ray_backend)."""
    if job.path is None or job.problem is not None or job.error:
        return job
    try:
        data = read_yaml(job.path)
    except InputError as exc:
        return dataclasses.replace(job, error=str(exc))
    return dataclasses.replace(job, problem=data, base_dir=str(Path(job.path).parent))


def make_jobs(problems: Iterable[Any]) -> list[Job]:
    """One Job per input, in order, with unique names."""
    jobs = [_job(i, item) for i, item in enumerate(problems)]
    names = _unique([j.name for j in jobs])
    return [dataclasses.replace(j, name=n) for j, n in zip(jobs, names, strict=True)]
