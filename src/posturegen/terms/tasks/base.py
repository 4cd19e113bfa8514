"""The task interface and its registry.

A task is a named error e(q) (one or more blocks of rows) met when lower <= e <= upper:

- **hard** (no ``weight``): constraint rows lower - tolerance <= e <= upper + tolerance;
- **soft** (``weight`` w): the cost w · Σ_blocks ‖violation_b / scale_b‖², the violation being
  e itself for an equality block and its excess beyond [lower, upper] for a range.

A task class writes two methods, :meth:`Task.errors` (against :class:`Frames`: the same code
declares the rows on CasADi and re-checks a posture on Pinocchio) and, for ranges,
:meth:`Task.limits`; its keys are :class:`Field` s in ``fields``. Registered
(:func:`register_task`), it is read from problem files, written to posture files, re-checked
by ``verify`` and named by ``diagnose`` like the built-in ones."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import casadi as ca
import numpy as np

from ... import _fields as F
from ..._registry import Registry
from ...errors import InputError
from ...hints import with_hint
from ...model.robot import Robot
from ..nlp import ArrayLike, BuildContext, Instance, Term
from .fields import Field, read_fields
from .frames import Expr, Frames, NumericFrames, ParameterValues, SymbolicFrames, joint_index

BIG = 1e10  # [unit] an open end of a soft task's range, as a parameter (not inf: its C code)
COMMON = ("type", "weight", "tolerance")  # keys every task has


@dataclass(kw_only=True)
class Task(Term):
    """A task of the posture problem (see the module doc). Subclasses are dataclasses whose
    fields are their ``fields``' keys (same names), and set ``kind`` (their ``type`` in files),
    ``unit`` (of the error: m, rad, or 1 for sines) and ``scale`` (the error that costs the
    weight, per block when ``scales`` says so)."""

    kind: ClassVar[str]
    fields: ClassVar[dict[str, Field]] = {}
    unit: ClassVar[str] = "m"
    scale: ClassVar[float] = 0.1

    weight: float | None = None  # soft when given: the cost's weight
    tolerance: float = 0.0  # [unit] of a hard task: rows met within it
    index: int = 0  # its place in the problem's task list

    def __post_init__(self) -> None:
        """Each key read as a file's would be (a task built in Python is checked too)."""
        fld = f"tasks[{self.index}]"
        for k, f in self.fields.items():
            value = getattr(self, k)
            if value is None and f.required:
                raise InputError(f"{fld}.{k}", "missing", f"give {k} ({f.doc})")
            if value is not None:
                setattr(self, k, f.read(value, f"{fld}.{k}"))
        if self.weight is not None:
            self.weight = F.number(self.weight, f"{fld}.weight", positive=True)
        self.tolerance = F.number(self.tolerance, f"{fld}.tolerance", minimum=0.0)
        self.check(fld)

    # ------------------------------------------------------------------ what a task writes
    def errors(self, f: Frames) -> dict[str, Expr]:
        """The error's blocks by name (each a vector, or a scalar)."""
        raise NotImplementedError(f"task type {self.kind!r} defines no errors()")

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        """(lower, upper) of the blocks that are ranges (the others: e = 0)."""
        return {}

    def subject(self) -> str:
        """What the task is about, in its name and its wording (default: its ``frame``)."""
        return str(getattr(self, "frame", self.kind))

    def target_point(self) -> np.ndarray | None:
        """A world point (3,) [m] the task brings a frame to, if any (for the reach warning
        and diagnosis)."""
        return None

    def scales(self) -> dict[str, float]:
        """Per block, the error [unit] that costs the weight (default: ``scale``)."""
        return {}

    # ------------------------------------------------------------------ derived
    @property
    def name(self) -> str:  # type: ignore[override]
        return f"task{self.index}.{self.subject()}"

    def key(self) -> tuple[Any, ...]:
        """The structure: the kind, the frames and joints named, which keys are given and the
        shapes of their values (the values themselves are parameters and bounds)."""
        return (
            self.kind,
            *(_structure(f, getattr(self, k)) for k, f in self.fields.items()),
            self.weight is not None,
            self.index,
        )

    def _limits(self, blocks: Mapping[str, Expr]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        given = self.limits()
        out = {}
        for block, e in blocks.items():
            n = int(np.size(e)) if isinstance(e, np.ndarray | float) else int(ca.SX(e).numel())
            lo, hi = given.get(block, (0.0, 0.0))
            out[block] = (
                np.broadcast_to(np.asarray(lo, dtype=float), (n,)).copy(),
                np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy(),
            )
        return out

    def declare(self, ctx: BuildContext) -> None:
        f = SymbolicFrames(ctx, self.name)
        blocks = self.errors(f)
        limits = self._limits(blocks)
        scales = self.scales()
        if self.weight is None:
            for block, e in blocks.items():
                lo, hi = limits[block]
                ctx.nlp.constrain(f"{self.name}.{block}", e, lo, hi)
            return
        cost: Any = 0
        ranges = self.limits()  # which blocks are ranges is structure, whatever their values
        for block, e in blocks.items():
            lo, hi = limits[block]
            s = scales.get(block, self.scale)
            if block not in ranges:
                cost += ca.sumsqr(e) / s**2
            else:
                lower = f.param(f"{block}.lower", np.zeros(len(lo)))
                upper = f.param(f"{block}.upper", np.zeros(len(hi)))
                excess = ca.fmax(e - upper, 0) + ca.fmin(e - lower, 0)
                cost += ca.sumsqr(excess) / s**2
        weight = f.param("weight", 1.0)
        ctx.nlp.minimize(self.name, weight * cost)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        recorder = ParameterValues(problem.robot.model, self.name)
        with np.errstate(all="ignore"):
            blocks = self.errors(recorder)
        out = dict(recorder.values)
        if self.weight is not None:
            ranges = self.limits()
            for block, (lo, hi) in self._limits(blocks).items():
                if block in ranges:
                    out[f"{self.name}.{block}.lower"] = np.clip(lo, -BIG, BIG)
                    out[f"{self.name}.{block}.upper"] = np.clip(hi, -BIG, BIG)
            out[f"{self.name}.weight"] = np.array([self.weight])
        return out

    def bounds(self, problem: Instance) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        if self.weight is not None:
            return {}
        recorder = ParameterValues(problem.robot.model, self.name)
        with np.errstate(all="ignore"):
            blocks = self.errors(recorder)
        tol = self.tolerance
        return {
            f"{self.name}.{b}": (lo - tol, hi + tol) for b, (lo, hi) in self._limits(blocks).items()
        }

    def violation(self, f: NumericFrames) -> dict[str, float]:
        """Per block, how far the error lies outside [lower - tolerance, upper + tolerance]
        [unit] at a posture (0 when met): what ``verify`` checks of a hard task."""
        blocks = self.errors(f)
        out = {}
        for block, (lo, hi) in self._limits(blocks).items():
            e = np.atleast_1d(np.asarray(blocks[block], dtype=float)).ravel()
            excess = np.maximum(e - hi - self.tolerance, 0) + np.maximum(lo - self.tolerance - e, 0)
            out[block] = float(excess.max(initial=0.0))
        return out

    def blocked(self, block: str, amount: float) -> str:
        """The diagnosis' sentence when the block is ``amount`` [unit] short of met."""
        what = "target" if block == self.kind else block.replace("_", " ")
        amount_text = f"{amount:.3g} {self.unit}"
        return (
            f"{what} of task {self.index} ({self.kind}) is {amount_text} beyond reach of "
            f"{self.subject()}"
        )

    def to_dict(self) -> dict[str, Any]:
        """The task's entry of a posture file (what :meth:`read` reads back)."""
        out: dict[str, Any] = {"type": self.kind}
        for k, f in self.fields.items():
            value = getattr(self, k)
            if value is not None:
                out[k] = f.write(value)
        out["weight"] = self.weight
        if self.tolerance:
            out["tolerance"] = self.tolerance
        return out

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, index: int) -> Task:
        """The task of a problem or posture file's entry (keys checked, one-line errors)."""
        entry = F.require_mapping(entry, fld)
        required = [k for k, f in cls.fields.items() if f.required]
        F.check_keys(entry, fld, ["type", *required], [*cls.fields, *COMMON])
        values = read_fields(cls.fields, entry, fld)
        weight = entry.get("weight")
        weight = None if weight is None else F.number(weight, f"{fld}.weight", positive=True)
        tol = F.number(entry.get("tolerance") or 0.0, f"{fld}.tolerance", minimum=0.0)
        try:
            return cls(**values, weight=weight, tolerance=tol, index=index)
        except InputError as exc:  # a check between keys: named as the entry is
            prefix = f"tasks[{index}]"
            if exc.field.startswith(prefix) and fld != prefix:
                raise InputError(fld + exc.field[len(prefix) :], exc.problem, exc.fix) from None
            raise

    def check(self, fld: str) -> None:
        """Checks between keys, after each was read (default: none)."""

    def check_robot(self, robot: Robot, fld: str) -> None:
        """Every frame and joint the task names exists on the robot (one-line errors)."""
        for k, f in self.fields.items():
            value = getattr(self, k)
            if f.form == "frame" and value is not None:
                robot.frame_id(value, f"{fld}.{k}")
            if f.form == "joint_values" and value is not None:
                for name in value:
                    _check_joint(robot, name, f"{fld}.{k}.{name}")


def _structure(f: Field, value: Any) -> Any:
    if value is None or f.form == "frame":
        return value
    if f.form == "joint_values":
        return tuple((name, np.shape(v)) for name, v in sorted(value.items()))
    return np.shape(value)


def _check_joint(robot: Robot, name: str, fld: str) -> None:
    try:
        joint_index(robot.model, name)
    except KeyError:
        known = [
            n
            for n in robot.model.names[1:]
            if robot.model.joints[robot.model.getJointId(n)].nq == 1
        ]
        raise InputError(
            fld,
            f"robot '{robot.name}' has no one-dof joint '{name}'",
            with_hint(name, known, "use a joint name of the URDF"),
        ) from None


# ---------------------------------------------------------------------------- registry
_TASKS: Registry[type[Task]] = Registry("task")
T = TypeVar("T", bound=type[Task])


def _check_fields(cls: type[Task]) -> None:
    missing = set(cls.fields) - {f.name for f in dataclasses.fields(cls)}
    if missing:
        raise InputError(
            f"{cls.__name__}",
            f"no attribute for the keys {sorted(missing)}",
            "declare each key of fields as a dataclass field of the same name",
        )


def register_task(cls: T) -> T:
    """Register a task class under its ``kind`` (a decorator): problem files, posture files,
    ``verify`` and ``diagnose`` then know it. A kind registered twice is an error."""
    _TASKS.register(cls, _check_fields)
    return cls


def task_types() -> dict[str, type[Task]]:
    """The registered task classes by their ``type`` name."""
    return _TASKS.types()


def read_task(entry: Any, fld: str, index: int) -> Task:
    """The task of a file's entry, by its ``type`` (one-line error for an unknown one)."""
    entry = F.require_mapping(entry, fld)
    return _TASKS.lookup(entry.get("type"), f"{fld}.type").read(entry, fld, index)
