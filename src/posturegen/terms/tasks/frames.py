"""What a task's error reads of a posture, symbolic or numeric: a task writes its error once,
against :class:`Frames`, and the same code builds the program's rows (:class:`SymbolicFrames`,
CasADi, the program's own kinematics) and re-checks a posture (:class:`NumericFrames`,
Pinocchio's kinematics, independent of the program's).

A task's *parameters* (its targets, ranges) are read through :meth:`Frames.param`: a parameter
of the program, so that a new target reuses the compiled program; the value itself when
checking."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..nlp import BuildContext

Expr = Any  # a CasADi SX or a numpy array, as the Frames are symbolic or numeric


class Frames(ABC):
    """Frame placements in world, the centre of mass, joint values and the task's parameters
    of one posture, with the few operations a task's error needs (numpy or CasADi alike)."""

    @abstractmethod
    def placement(self, frame: str) -> tuple[Expr, Expr]:
        """(R_world_frame (3, 3), p_world_frame (3,) [m]) of a frame of the robot."""

    @abstractmethod
    def com(self) -> Expr:
        """The robot's centre of mass in world (3,) [m]."""

    @abstractmethod
    def joint(self, name: str) -> Expr:
        """The value of a one-dof joint [rad] or [m]."""

    @abstractmethod
    def param(self, name: str, value: Any) -> Expr:
        """A parameter of the task (its numeric value: ``value``), flattened (n,)."""

    def rotation_param(self, name: str, R: Any) -> Expr:
        """A rotation (3, 3) parameter of the task (value R), column-major as the program's
        parameters are."""
        return self._matrix3(self.param(name, np.asarray(R, dtype=float).ravel(order="F")))

    @abstractmethod
    def _matrix3(self, v: Expr) -> Expr:
        """A (9,) column-major vector as a (3, 3) matrix."""

    def position(self, frame: str) -> Expr:
        """p_world_frame (3,) [m]."""
        return self.placement(frame)[1]

    def rotation(self, frame: str) -> Expr:
        """R_world_frame (3, 3)."""
        return self.placement(frame)[0]

    # the operations, numpy or CasADi
    @abstractmethod
    def vertcat(self, *parts: Expr) -> Expr:
        """The parts (scalars or vectors) stacked into one vector."""

    @abstractmethod
    def cross(self, a: Expr, b: Expr) -> Expr:
        """a × b (3,)."""

    @abstractmethod
    def sqrt(self, x: Expr) -> Expr:
        """√x."""

    @abstractmethod
    def dot(self, a: Expr, b: Expr) -> Expr:
        """aᵀb."""

    def norm(self, a: Expr, eps: float = 1e-12) -> Expr:
        """‖a‖, smoothed by eps [unit²] at 0 (its derivative stays finite)."""
        return self.sqrt(self.dot(a, a) + eps)


class SymbolicFrames(Frames):
    """The program's kinematics (:class:`posturegen.model.kinematics.CasadiKinematics`) while a
    task declares its rows; parameters become the program's ``<task name>.<param>``."""

    def __init__(self, ctx: BuildContext, prefix: str) -> None:
        self.ctx = ctx
        self.prefix = prefix
        self._params: dict[str, ca.SX] = {}

    def placement(self, frame: str) -> tuple[Expr, Expr]:
        R, p = self.ctx.kin.frame_placement(self.ctx.state, self.ctx.robot.frame_id(frame))
        return R, p

    def com(self) -> Expr:
        return self.ctx.kin.com_world(self.ctx.state)

    def joint(self, name: str) -> Expr:
        return self.ctx.joints[joint_index(self.ctx.robot.model, name)]

    def param(self, name: str, value: Any) -> Expr:
        if name not in self._params:
            n = int(np.asarray(value, dtype=float).size)
            self._params[name] = self.ctx.nlp.parameter(f"{self.prefix}.{name}", n)
        return self._params[name]

    def _matrix3(self, v: Expr) -> Expr:
        return ca.reshape(v, 3, 3)

    def vertcat(self, *parts: Expr) -> Expr:
        return ca.vertcat(*parts)

    def cross(self, a: Expr, b: Expr) -> Expr:
        return ca.cross(a, b)

    def sqrt(self, x: Expr) -> Expr:
        return ca.sqrt(x)

    def dot(self, a: Expr, b: Expr) -> Expr:
        return ca.dot(a, b)


class NumericFrames(Frames):
    """Pinocchio's kinematics of a posture (``data`` after ``framesForwardKinematics`` at q):
    what :func:`posturegen.verify.verify_posture` re-checks a task with."""

    def __init__(self, model: pin.Model, data: pin.Data, q: np.ndarray) -> None:
        self.model, self.data, self.q = model, data, np.asarray(q, dtype=float)
        self._com: np.ndarray | None = None

    def placement(self, frame: str) -> tuple[Expr, Expr]:
        if not self.model.existFrame(frame):
            raise KeyError(frame)
        M = self.data.oMf[self.model.getFrameId(frame)]
        return np.array(M.rotation), np.array(M.translation)

    def com(self) -> Expr:
        if self._com is None:
            self._com = np.array(pin.centerOfMass(self.model, self.data, self.q, False))
        return self._com

    def joint(self, name: str) -> Expr:
        return float(self.q[7 + joint_index(self.model, name)])

    def param(self, name: str, value: Any) -> Expr:
        return np.asarray(value, dtype=float).ravel()

    def _matrix3(self, v: Expr) -> Expr:
        return np.asarray(v, dtype=float).reshape(3, 3, order="F")

    def vertcat(self, *parts: Expr) -> Expr:
        return np.concatenate([np.atleast_1d(np.asarray(p, dtype=float)).ravel() for p in parts])

    def cross(self, a: Expr, b: Expr) -> Expr:
        return np.cross(np.ravel(a), np.ravel(b))

    def sqrt(self, x: Expr) -> Expr:
        return np.sqrt(x)

    def dot(self, a: Expr, b: Expr) -> Expr:
        return float(np.dot(np.ravel(a), np.ravel(b)))


class ParameterValues(NumericFrames):
    """Frames at a stand-in posture that only collect the task's parameter values (what
    :meth:`posturegen.terms.tasks.base.Task.parameters` gives the program)."""

    def __init__(self, model: pin.Model, prefix: str) -> None:
        self.model, self.prefix, self.values = model, prefix, {}
        self.q = pin.neutral(model)
        self._com = np.zeros(3)

    def placement(self, frame: str) -> tuple[Expr, Expr]:
        return np.eye(3), np.zeros(3)

    def param(self, name: str, value: Any) -> Expr:
        v = np.asarray(value, dtype=float).ravel()
        self.values[f"{self.prefix}.{name}"] = v
        return v


def joint_index(model: pin.Model, name: str) -> int:
    """The index of a one-dof joint among the joint coordinates after the free flyer's 7."""
    if not model.existJointName(name):
        raise KeyError(name)
    joint = model.joints[model.getJointId(name)]
    if joint.nq != 1:
        raise KeyError(name)
    return int(joint.idx_q) - 7
