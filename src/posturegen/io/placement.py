"""The initial posture placed on the fixed contacts: the robot's default posture turned about
the vertical and moved so that its patches lie as well as they can on their fixed targets.

The base rotation is a local map around the initial orientation (|w_i| <= 2.5 rad, see
``posturegen.terms.configuration``), so a robot that starts facing +x cannot turn to stand on feet
fixed at a heading of π; started where its fixed contacts are, it only has to adjust.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from ..model.robot import Robot

# [m] the arm of the frame points that carry a patch's orientation into the fit
_AXIS_LENGTH = 0.1
# a fixed contact is stood on when its patch's outward normal points down within 30°
_COS_30 = float(np.cos(np.radians(30.0)))


def _frame_points(T: pin.SE3) -> np.ndarray:
    """(4, 3) world points of a frame: its origin and the tips of its three axes."""
    return T.translation + np.vstack([np.zeros(3), _AXIS_LENGTH * T.rotation.T])


def fit_yaw_translation(a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """(ψ, t) minimizing Σ|Rz(ψ)·a_i + t - b_i|² for points a, b (n, 3): the 2-D Procrustes
    rotation of the centred horizontal coordinates, t = b̄ - Rz(ψ)·ā."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    da, db = a - ca, b - cb
    s = float(np.sum(da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]))
    c = float(np.sum(da[:, 0] * db[:, 0] + da[:, 1] * db[:, 1]))
    yaw = float(np.arctan2(s, c))
    return yaw, cb - pin.utils.rotate("z", yaw) @ ca


def place_on_fixed_contacts(robot: Robot, q: np.ndarray, contacts: Sequence[Any]) -> np.ndarray:
    """q (nq,) with its base turned by ψ about the world z axis and moved by t (the same
    joints): ψ and the horizontal t the least-squares fit of the fixed contacts' patch frames
    at q to their targets (origins and axis tips, :func:`fit_yaw_translation`); t_z the mean
    rise from the patch origins to their targets of the contacts stood on (patch normal
    within 30° of straight down), 0 without one. Without a fixed contact, q unchanged."""
    q = np.array(q, dtype=float)
    fixed = [c for c in contacts if c.fixed_in_place]
    if not fixed:
        return q
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    here = [_frame_points(data.oMf[c.patch.frame_id] * c.patch.T_frame_patch) for c in fixed]
    there = [_frame_points(c.T_world_target) for c in fixed]
    yaw, t = fit_yaw_translation(np.vstack(here), np.vstack(there))
    # the height comes from what the robot stands on (a hand on a wall would lift its feet)
    standing = [k for k, c in enumerate(fixed) if c.T_world_target.rotation[2, 2] < -_COS_30]
    t[2] = np.mean([there[k][0, 2] - here[k][0, 2] for k in standing]) if standing else 0.0
    Rz = pin.utils.rotate("z", yaw)
    R_base = pin.Quaternion(q[3:7]).normalized().matrix()
    q[0:3] = Rz @ q[0:3] + t
    q[3:7] = pin.Quaternion(Rz @ R_base).normalized().coeffs()
    return q
