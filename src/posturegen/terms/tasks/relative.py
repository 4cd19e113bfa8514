"""``relative``: a frame's pose in another frame of the robot (two hands holding one object)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pinocchio as pin

from ..nlp import ArrayLike
from .base import Task, register_task
from .fields import Field
from .frames import Expr, Frames
from .position import rotation_error


@register_task
@dataclass
class RelativeTask(Task):
    """p_ref_frame = R_world_refᵀ (p_world_frame - p_world_ref) = target (3,) [m], and with
    ``rpy`` R_ref_frame = R(rpy) (rows as the orientation task's)."""

    kind: ClassVar[str] = "relative"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame placed"),
        "reference": Field("frame", "the robot's frame it is placed in"),
        "target": Field("vector", "[m] the frame's origin in the reference frame"),
        "rpy": Field("rpy", "[rad] the frame's orientation in the reference frame", default=None),
    }

    frame: str
    reference: str
    target: np.ndarray  # (3,) [m]
    rpy: np.ndarray | None = None  # (3,) [rad]

    def subject(self) -> str:
        return f"{self.frame}-in-{self.reference}"

    def errors(self, f: Frames) -> dict[str, Expr]:
        R_ref, p_ref = f.placement(self.reference)
        R, p = f.placement(self.frame)
        out = {"position": R_ref.T @ (p - p_ref) - f.param("target", self.target)}
        if self.rpy is not None:
            Rt = f.rotation_param("R_target", pin.rpy.rpyToMatrix(*self.rpy))
            out["orientation"], out["orientation_branch"] = rotation_error(
                f.vertcat, Rt, R_ref.T @ R
            )
        return out

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        return {"orientation_branch": (0.0, np.inf)}

    def scales(self) -> dict[str, float]:
        return {"orientation": 0.1, "orientation_branch": 1.0}
