"""Frame tasks: a frame's position (and optionally orientation) at a target, hard or as a
weighted cost."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .nlp import BuildContext, Instance, Term


@dataclass
class PositionTask(Term):
    """Frame position = target (3,) [m] in world, optionally orientation = R_target.

    The orientation error is e = vee(skew(R_targetᵀ R)) = sin θ · axis (3,), θ and axis those
    of R_targetᵀ R: hard rows e = 0 with tr(R_targetᵀ R) >= 0 (θ = 0, not π), or with ``weight``
    the cost weight·(|p - target|² / (0.1 m)² + |e|²) (|e|² = sin²θ).
    """

    kind = "position"  # its "type" in problem and posture files

    frame: str
    frame_id: int
    target: np.ndarray  # (3,) [m]
    R_target: np.ndarray | None = None  # (3, 3) or None
    weight: float | None = None
    index: int = 0

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"task{self.index}.{self.frame}"

    def key(self) -> tuple[Any, ...]:
        return ("position", self.frame_id, self.R_target is not None, self.weight is not None)

    def declare(self, ctx: BuildContext) -> None:
        nlp = ctx.nlp
        R, p = ctx.kin.frame_placement(ctx.state, self.frame_id)
        target = nlp.parameter(f"{self.name}.target", 3)
        err = p - target
        rot_err = None
        if self.R_target is not None:
            Rt = ca.reshape(nlp.parameter(f"{self.name}.R_target", 9), 3, 3)
            E = Rt.T @ R
            rot_err = 0.5 * ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])
        if self.weight is None:
            nlp.constrain(f"{self.name}.position", err, 0.0, 0.0)
            if rot_err is not None:
                nlp.constrain(f"{self.name}.orientation", rot_err, 0.0, 0.0)
                # the skew part vanishes for 0 and π: keep the trace positive (same branch)
                nlp.constrain(f"{self.name}.orientation_branch", ca.trace(E), 0.0, np.inf)
        else:
            cost = ca.sumsqr(err) / 0.01
            if rot_err is not None:
                cost += ca.sumsqr(rot_err)
            nlp.minimize(self.name, self.weight * cost)
        nlp.output(f"{self.name}.position", p)
        nlp.output(f"{self.name}.rotation", R)

    def to_dict(self) -> dict[str, Any]:
        """The task's entry of the posture file."""
        return {
            "type": self.kind,
            "frame": self.frame,
            "target": np.asarray(self.target).tolist(),
            "rotation": None if self.R_target is None else np.asarray(self.R_target).tolist(),
            "weight": self.weight,
        }

    def parameters(self, problem: Instance) -> dict[str, np.ndarray]:
        out = {f"{self.name}.target": self.target}
        if self.R_target is not None:
            out[f"{self.name}.R_target"] = self.R_target
        return out
