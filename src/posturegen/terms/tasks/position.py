"""``position``: a frame's position at a world point, optionally its orientation too."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca
import numpy as np
import pinocchio as pin

from ..nlp import ArrayLike, BuildContext, Instance
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames


def rotation_error(vertcat: Callable[..., Expr], R_target: Expr, R: Expr) -> tuple[Expr, Expr]:
    """(sin θ · axis (3,), tr(R_targetᵀ R)) of the rotation R_targetᵀ R = exp(θ axis): the
    error rows vanish for θ = 0 and π, the trace >= 0 keeps θ = 0."""
    E = R_target.T @ R
    e = vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]) * 0.5
    return e, E[0, 0] + E[1, 1] + E[2, 2]


@register_task
@dataclass
class PositionTask(Task):
    """p_world_frame = target (3,) [m], and with ``rpy`` R_world_frame = R(rpy).

    Hard: rows p - target = 0, e = vee(skew(R_targetᵀ R)) = sin θ · axis = 0 and
    tr(R_targetᵀ R) >= 0. Soft: weight · (‖p - target‖² / (0.1 m)² + ‖e‖²)."""

    kind: ClassVar[str] = "position"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame (a link or frame of the URDF)"),
        "target": Field("vector", "[m] the frame's origin in world"),
        "rpy": Field("rpy", "[rad] the frame's orientation in world, roll-pitch-yaw", default=None),
    }

    frame: str
    target: np.ndarray  # (3,) [m]
    rpy: np.ndarray | None = None  # (3,) [rad]

    @property
    def R_target(self) -> np.ndarray | None:
        """R_world_frame wanted (3, 3), None without ``rpy``."""
        return None if self.rpy is None else pin.rpy.rpyToMatrix(*self.rpy)

    def target_point(self) -> np.ndarray | None:
        return np.asarray(self.target, dtype=float)

    def key(self) -> tuple[Any, ...]:
        # the soft cost's weight is a constant of the program (its expression, kept as it was)
        return (*super().key(), self.weight)

    def errors(self, f: Frames) -> dict[str, Expr]:
        R, p = f.placement(self.frame)
        out = {"position": p - f.param("target", self.target)}
        if self.rpy is not None:
            Rt = f.rotation_param("R_target", self.R_target)
            out["orientation"], out["orientation_branch"] = rotation_error(f.vertcat, Rt, R)
        return out

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        return {"orientation_branch": (0.0, np.inf)}

    def scales(self) -> dict[str, float]:
        return {"position": 0.1, "orientation": 1.0}

    def declare(self, ctx: BuildContext) -> None:
        if self.weight is None:
            super().declare(ctx)
        else:  # the position and orientation errors; the branch is for the hard rows only
            nlp = ctx.nlp
            R, p = ctx.kin.frame_placement(ctx.state, ctx.robot.frame_id(self.frame))
            cost = ca.sumsqr(p - nlp.parameter(f"{self.name}.target", 3)) / 0.01
            if self.rpy is not None:
                Rt = ca.reshape(nlp.parameter(f"{self.name}.R_target", 9), 3, 3)
                cost += ca.sumsqr(rotation_error(ca.vertcat, Rt, R)[0])
            nlp.minimize(self.name, self.weight * cost)
        R, p = ctx.kin.frame_placement(ctx.state, ctx.robot.frame_id(self.frame))
        ctx.nlp.output(f"{self.name}.position", p)
        ctx.nlp.output(f"{self.name}.rotation", R)

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {f"{self.name}.target": np.asarray(self.target, dtype=float)}
        if self.rpy is not None:
            out[f"{self.name}.R_target"] = np.asarray(self.R_target).ravel(order="F")
        return out

    def blocked(self, block: str, amount: float) -> str:
        if block == "position":
            return f"target of task {self.index} is {amount:.3g} m beyond reach of {self.frame}"
        return (
            f"orientation of task {self.index} is {amount:.3g} (sine) beyond reach of {self.frame}"
        )

    @classmethod
    def read(cls, entry: Mapping[str, Any], fld: str, index: int) -> Task:
        if isinstance(entry, Mapping) and entry.get("rotation") is not None:  # a posture file
            entry = dict(entry)  # of before rpy: its rotation matrix
            R = np.asarray(entry.pop("rotation"), dtype=float).reshape(3, 3)
            entry["rpy"] = pin.rpy.matrixToRpy(R).tolist()
        elif isinstance(entry, Mapping) and "rotation" in entry:
            entry = {k: v for k, v in entry.items() if k != "rotation"}
        return super().read(entry, fld, index)


@register_task
@dataclass
class PoseTask(PositionTask):
    """The frame's full pose: ``position`` with ``rpy`` required."""

    kind: ClassVar[str] = "pose"
    fields: ClassVar[dict[str, Field]] = {
        **PositionTask.fields,
        "rpy": Field("rpy", "[rad] the frame's orientation in world, roll-pitch-yaw"),
    }
