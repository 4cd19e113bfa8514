"""What the shipped scenes (posturegen.climb.scenes) are built from: robot specs and sizes,
rectangular surfaces and boxes, the ground, fixed and kept feet, soft foot tasks, and the
climbs' costs and options."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..model.robot import BUNDLED, load_robot

ROBOT_NAMES = BUNDLED


def robot_spec(name: str) -> Any:
    """The ``robot`` entry of a problem for a robot name (every shipped robot, HRP-2 and
    ATLAS included, is named by itself)."""
    if name not in BUNDLED:
        raise InputError(
            "--robot", f"unknown robot '{name}'", f"use one of: {', '.join(ROBOT_NAMES)}"
        )
    return name


# --------------------------------------------------------------------------- geometry helpers
def rect(
    name: str, centre: list[float], size: tuple[float, float], rpy: Any = (0, 0, 0)
) -> dict[str, Any]:
    """A rectangular support surface ``size`` = (x, y) [m] centred at ``centre``."""
    hx, hy = size[0] / 2, size[1] / 2
    return {
        "name": name,
        "position": [float(v) for v in centre],
        "rpy": [float(v) for v in rpy],
        "vertices": [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]],
    }


def box(name: str, centre: list[float], size: list[float], rpy: Any = (0, 0, 0)) -> dict[str, Any]:
    """A box obstacle of full extents ``size`` [m]."""
    return {
        "name": name,
        "box": [float(v) for v in size],
        "position": [float(v) for v in centre],
        "rpy": [float(v) for v in rpy],
    }


GROUND = rect("ground", [0.0, 0.0, 0.0], (3.0, 3.0))


@dataclass(frozen=True)
class RobotSize:
    """Numbers that scale a scene to a robot [m]: sole length and width, leg length (sole to
    hip), shoulder height above the soles, half the distance between the soles, and the
    shoulder's distance from the sagittal plane, all at the default posture."""

    sole_length: float
    sole_width: float
    hip_height: float
    shoulder_height: float
    stance_half_width: float
    shoulder_half_width: float


def robot_size(robot_name: str) -> RobotSize:
    """Measure a robot at its default posture (patch extents and frame heights)."""
    robot = load_robot(robot_spec(robot_name))
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.q_init)
    sole = robot.patch("right_sole")
    v = sole.polygon.vertices
    z_sole = data.oMf[sole.frame_id].translation[2]
    hand = robot.patch("right_hand")

    def top_of_chain(j: int) -> np.ndarray:
        """Position (3,) of the highest joint between joint j and the root (the shoulder of
        a hand, the hip of a foot) [m]."""
        top = data.oMi[j].translation
        while j > 1:
            if data.oMi[j].translation[2] > top[2]:
                top = data.oMi[j].translation
            j = model.parents[j]
        return np.array(top)

    y_left = data.oMf[robot.patch("left_sole").frame_id].translation[1]
    y_right = data.oMf[sole.frame_id].translation[1]
    return RobotSize(
        float(np.ptp(v[:, 0])),
        float(np.ptp(v[:, 1])),
        float(top_of_chain(sole.joint_id)[2] - z_sole),
        float(top_of_chain(hand.joint_id)[2] - z_sole),
        # the feet where the default posture has them (at least 10 cm apart from the middle):
        # a narrower stance can push the legs' proxies into each other
        float(max(0.1, abs(y_left - y_right) / 2)),
        float(abs(top_of_chain(hand.joint_id)[1])),
    )


def _feet_on_ground(x: float = 0.0, half_width: float = 0.1) -> list[dict[str, Any]]:
    return [
        {
            "robot_patch": "left_sole",
            "surface": "ground",
            "type": "fixed",
            "position": [x, half_width],
        },
        {
            "robot_patch": "right_sole",
            "surface": "ground",
            "type": "fixed",
            "position": [x, -half_width],
        },
    ]


def _keep(*names: str) -> list[dict[str, Any]]:
    return [{"name": n, "type": "keep"} for n in names]


CLIMB_COSTS: dict[str, Any] = {"posture": 1.0, "posture_reference": "default", "forces": 1.0}
COMMON_OPTIONS: dict[str, Any] = {
    "self_collision": True,
    "environment_collision": True,
    "solver": {"max_iter": 400},
}
# The paper's ladders are at the robots' strength: with the default CoP margin (5 mm) the last
# stage of HRP-2's vertical ladder needs 1.41× CHEST_JOINT1's torque limit, with 3 mm that of
# TALOS' inclined ladder 1.22× leg_right_3_joint's (posturegen's diagnosis); with 2 mm every
# ladder stage and climb solves.
LADDER_OPTIONS: dict[str, Any] = {**COMMON_OPTIONS, "cop_margin": 0.002}


def _sole_frames(robot: str) -> dict[str, str]:
    """The frames of the robot's sole patches, by patch name."""
    model = load_robot(robot_spec(robot))
    return {p: model.patch(p).frame for p in ("left_sole", "right_sole")}


def _foot_task(frame: str, target: list[float], weight: float) -> dict[str, Any]:
    """A soft position task on a sole frame."""
    return {"type": "position", "frame": frame, "target": target, "weight": weight}
