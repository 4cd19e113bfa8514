"""``orientation``: a frame's orientation in world, position free."""

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
class OrientationTask(Task):
    """R_world_frame = R(rpy): rows e = vee(skew(R_targetᵀ R)) = sin θ · axis = 0 and
    tr(R_targetᵀ R) >= 0 (θ = 0, not π); soft: weight · ‖e‖² / (0.1)² (about 6°)."""

    kind: ClassVar[str] = "orientation"
    unit: ClassVar[str] = "(sine)"
    fields: ClassVar[dict[str, Field]] = {
        "frame": Field("frame", "the robot's frame"),
        "rpy": Field("rpy", "[rad] the frame's orientation in world, roll-pitch-yaw"),
    }

    frame: str
    rpy: np.ndarray  # (3,) [rad]

    def errors(self, f: Frames) -> dict[str, Expr]:
        Rt = f.rotation_param("R_target", pin.rpy.rpyToMatrix(*self.rpy))
        e, trace = rotation_error(f.vertcat, Rt, f.rotation(self.frame))
        return {"orientation": e, "orientation_branch": trace}

    def limits(self) -> dict[str, tuple[ArrayLike, ArrayLike]]:
        return {"orientation_branch": (0.0, np.inf)}

    def scales(self) -> dict[str, float]:
        return {"orientation_branch": 1.0}
