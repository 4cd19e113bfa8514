"""The shipped scenes (paper sec. V) as contact sequences, for any robot with the four named
patches ``left_sole``, ``right_sole``, ``left_hand``, ``right_hand``.

Each scene builder returns a sequence dict (see :mod:`posturegen.climb.sequence`): the scene's
surfaces and obstacles and the stages that lead to the paper's situation (``demo``) or climb
``steps`` steps (``climb``). Geometry is in metres, world frame: x forward (towards the
ladder or stairs), z up, the robot starting around the origin.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import InputError
from ..model.robot import load_robot
from ..solver.problem import with_sequence_method
from .parts import (
    CLIMB_COSTS,
    COMMON_OPTIONS,
    GROUND,
    LADDER_OPTIONS,
    RobotSize,
    _feet_on_ground,
    _foot_task,
    _keep,
    _sole_frames,
    box,
    rect,
    robot_size,
    robot_spec,
)


# --------------------------------------------------------------------------- scenes
def stand_reach(robot: str, steps: int = 1) -> dict[str, Any]:
    """Both feet fixed on flat ground, the right hand's patch at a point in front."""
    r = load_robot(robot_spec(robot))
    frame = r.patch("right_hand").frame
    size = robot_size(robot)
    target = [0.3 * size.shoulder_height, -0.25, 0.75 * size.shoulder_height]
    return {
        "name": "stand-reach",
        "description": "both feet fixed on the ground, right hand at a target in front",
        "robot": robot_spec(robot),
        "mu": 0.7,
        "surfaces": [GROUND],
        "obstacles": [],
        "options": COMMON_OPTIONS,
        "stages": [
            {
                "name": "reach",
                "contacts": _feet_on_ground(half_width=size.stance_half_width),
                "tasks": [{"type": "position", "frame": frame, "target": target}],
            }
        ],
    }


def wall_brace(robot: str, steps: int = 1) -> dict[str, Any]:
    """The left hand braced on a wall to the left, the right hand reaching far to the
    right-front: without the brace the target is out of the balance region."""
    r = load_robot(robot_spec(robot))
    frame = r.patch("right_hand").frame
    size = robot_size(robot)
    wall_y = 0.35 + 0.12 * size.shoulder_height
    wall = rect(
        "wall",
        [0.1, wall_y, 0.8 * size.shoulder_height],
        (1.2, 1.2),
        rpy=(math.pi / 2, 0.0, 0.0),  # outward normal -y: facing the robot
    )
    target = [0.45 * size.shoulder_height + 0.25, -0.35, 0.55 * size.shoulder_height]
    return {
        "name": "wall-brace",
        "description": "left hand braced on a wall, right hand reaching far to the front-right",
        "robot": robot_spec(robot),
        "mu": 0.7,
        "surfaces": [GROUND, wall],
        "obstacles": [],
        "options": COMMON_OPTIONS,
        "stages": [
            {
                "name": "brace and reach",
                "contacts": [
                    *_feet_on_ground(half_width=size.stance_half_width),
                    {
                        "robot_patch": "left_hand",
                        "surface": "wall",
                        "type": "support",
                        "min_radii": [0.02, 0.02],
                    },
                ],
                "tasks": [{"type": "position", "frame": frame, "target": target}],
            }
        ],
    }


def _steps_geometry(
    n: int, x0: float, rise: float, depth: float, width: float, last_depth: float
) -> list[dict[str, Any]]:
    """Stairs: step k (1..n) is a block ``depth`` deep and ``rise`` high whose top, at
    z = k·rise, is the support surface ``stepk`` (its front edge at x0 + (k-1)·depth; the last
    step ``last_depth`` deep). The block is avoided by every link not in contact with that
    step, so its front face is the riser that stops a toe on the step below, while a foot on
    the step may overhang its front edge."""
    surfaces = []
    for k in range(1, n + 1):
        d = last_depth if k == n else depth
        x_front = x0 + (k - 1) * depth
        s = rect(f"step{k}", [x_front + d / 2, 0.0, k * rise], (d, width))
        s["thickness"] = rise
        surfaces.append(s)
    return surfaces


# [rad] each foot's yaw on a step, either way from straight up the stairs: free, the maximized
# ellipse turns the foot across the short step (ATLAS: -1.28 rad on step 1, and its climb
# failed at step 4). 0.35 until every pair was avoided (issue 14): Talos' thigh then met its
# pelvis putting its right foot on step 3 (IPOPT infeasible at 0.35 and 0.5, verified at 0.6)
STAIR_FOOT_YAW = 0.6


def stairs(robot: str, steps: int = 2) -> dict[str, Any]:
    """Paper V-C: steps shorter than the foot (0.65× its length), each next riser an obstacle;
    each stage puts one foot on the next step maximizing the contact ellipse (eq. 8), so the
    foot overhangs the edge as far as the riser allows, pointing up the stairs within
    ±STAIR_FOOT_YAW; the last step is deep enough for the whole foot."""
    size = robot_size(robot)
    depth = round(0.65 * size.sole_length, 3)
    rise = 0.12
    n = max(1, steps)
    surfaces = _steps_geometry(
        n + 1, 0.5 * size.sole_length + 0.25, rise, depth, 0.8, 2.2 * size.sole_length
    )
    stages: list[dict[str, Any]] = [
        {"name": "stand", "contacts": _feet_on_ground(half_width=size.stance_half_width)}
    ]
    moving, other = "right_sole", "left_sole"
    for k in range(1, n + 1):
        stages.append(
            {
                "name": f"{moving.split('_')[0]} foot on step {k}",
                "contacts": [
                    *_keep(other),
                    {
                        "robot_patch": moving,
                        "surface": f"step{k}",
                        "type": "support",
                        "min_radii": [0.02, 0.02],
                        "maximize_area": 10.0,
                        "yaw_range": [-STAIR_FOOT_YAW, STAIR_FOOT_YAW],
                    },
                ],
            }
        )
        moving, other = other, moving
    return {
        "name": "stairs",
        "description": (
            f"steps {depth:.2f} m deep for a {size.sole_length:.2f} m sole, rise {rise:.2f} m; "
            "contact ellipses maximized against the risers"
        ),
        "robot": robot_spec(robot),
        "mu": 0.7,
        "surfaces": [GROUND, *surfaces],
        "obstacles": [],
        "initial": {"base": [0.0, 0.0, 0.0]},
        "options": COMMON_OPTIONS,
        "costs": CLIMB_COSTS,
        "stages": stages,
    }


# Soft tasks (costs weight·|p - target|²/(0.1 m)², not constraints) that guide a foot on the
# ladders: the first foot towards the middle of step or rung 1, and on the inclined ladder the
# lifted left foot towards step 2.
FOOTHOLD_WEIGHT = 1.0
# 0.3 until every pair was avoided (issue 14): Talos' lifted left foot then stopped under step
# 2 (IPOPT did not converge at 0.3 and 0.6); at 1.0 both Talos and HRP-2 are verified
LIFT_WEIGHT = 1.0
STEP_FOOT_Y = 0.05  # [m] the first foot's target on step 1, right of the middle
# the lifted foot's target: level with step 2, its toes this far behind step 3's front edge
# (measured: 2 to 6 cm solve on HRP-2 and Talos, 0 not on Talos; with the target 5 cm higher,
# HRP-2 failed at 0, 3 and 5 cm: its toes went under step 2's front edge, between its foot's
# proxies, and the mesh check rejected the posture)
TOE_CLEARANCE = 0.04  # [m]


# the rails' hand face turns 75° from up-back towards the ladder's middle (measured: at 0° the
# HRP-2 hand, whose patch is the back of the hand, cannot lie on it; 45° failed on HRP-2 and
# 90° on Talos), and the rails clear the shoulders by 20 cm (10 cm let Talos' torso proxies
# reach them)
RAIL_TILT = math.radians(75.0)
RAIL_CLEARANCE = 0.2  # [m]
LADDER_GAP = 0.255  # [m] from the toes at the start to step 1's front edge
# [N] a hand closed around a rail presses it this much beyond its load (posturegen.terms.forces:
# it may pull by that much, and its friction grows with it). Open (a palm on the rail's face,
# μ 0.7), HRP-2 could not take its lower foot off step 1 with its upper foot on step 2 and both
# hands on the rails: beyond its torque limits (verified at 3x them), and at grip 100 N
RAIL_GRIP = 150.0


def _rail_rpy(alpha: float, inward: float) -> tuple[float, float, float]:
    """rpy of a surface whose x axis climbs at ``alpha`` in the x-z plane, its normal turned
    from up-back towards +y by ``inward`` [rad]."""
    return (-inward, -alpha, 0.0)


def _inclined_surfaces(
    size: RobotSize,
    alpha: float,
    pitch: tuple[float, float, float],
    step: tuple[float, float],
    n_steps: int,
) -> list[dict[str, Any]]:
    """The ground, ``n_steps`` steps (step k at x0 + k·run, height k·rise; pitch = (x0, run,
    rise), step = (depth, width)) and the two guardrails climbing at ``alpha``."""
    (x0, run, rise), (depth, width) = pitch, step
    surfaces = [GROUND]
    for k in range(1, n_steps + 1):
        s = rect(f"step{k}", [x0 + k * run, 0.0, k * rise], (depth, width))
        s["thickness"] = 0.03
        surfaces.append(s)
    rail_h = 0.55 * size.shoulder_height  # rail height above the steps' front line
    rail_len = 3.0
    for side, y in (("left", width / 2 + 0.04), ("right", -width / 2 - 0.04)):
        # the rail's centre line climbs from (x0, rail_h), above the ladder's foot
        xc = x0 + 0.5 * rail_len * math.cos(alpha)
        zc = rail_h + 0.5 * rail_len * math.sin(alpha)
        tilt = RAIL_TILT if side == "right" else -RAIL_TILT
        s = rect(f"{side}_rail", [xc, y, zc], (rail_len, 0.05), _rail_rpy(alpha, tilt))
        s["thickness"] = 0.04
        surfaces.append(s)
    return surfaces


def _inclined_stages(
    size: RobotSize, frames: dict[str, str], pitch: tuple[float, float, float], depth: float
) -> list[dict[str, Any]]:
    """The inclined ladder's stages (pitch = (x0, run, rise), see :func:`_inclined_surfaces`)."""
    x0, run, rise = pitch
    # every foothold is as solid as the paper asks of the last one; the hand rests on the
    # rail with an ellipse at least 3 cm across (the rail is 5 cm wide)
    foothold = {"min_radii": [0.4 * depth, 0.4 * depth]}
    geo = {"type": "geometric", **foothold}
    grip = {"type": "support", "min_radii": [0.015, 0.015], "grip": RAIL_GRIP}
    return [
        {"name": "stand", "contacts": _feet_on_ground(half_width=size.stance_half_width)},
        {
            "name": "right foot on step 1",
            "contacts": [
                *_keep("left_sole"),
                {"robot_patch": "right_sole", "surface": "step1", "type": "support", **foothold},
            ],
            # left alone, the foot lands 23 cm right of the middle, and Talos, whose wrists hold
            # little, cannot then lift its left foot (it solves only beyond its torque limits,
            # swinging its left arm and leg to the right as counterweights)
            "tasks": [
                _foot_task(frames["right_sole"], [x0 + run, -STEP_FOOT_Y, rise], FOOTHOLD_WEIGHT)
            ],
        },
        {
            "name": "right hand on the right rail",
            "contacts": [
                *_keep("left_sole", "right_sole"),
                {"robot_patch": "right_hand", "surface": "right_rail", **grip},
            ],
        },
        {
            # the foot off the ground first: without this stage Talos' last stage fails (its
            # left shin met step 3), its right foot guided or not
            "name": "left foot lifted",
            "contacts": _keep("right_sole", "right_hand"),
            "tasks": [
                _foot_task(
                    frames["left_sole"],
                    [
                        x0 + 3 * run - 0.5 * depth - 0.5 * size.sole_length - TOE_CLEARANCE,
                        size.stance_half_width,
                        2 * rise,
                    ],
                    LIFT_WEIGHT,
                )
            ],
        },
        {
            "name": "left foot on step 2",
            "contacts": [
                *_keep("right_sole", "right_hand"),
                {"robot_patch": "left_sole", "surface": "step2", **geo},
            ],
        },
    ]


def ladder_inclined(robot: str, steps: int = 1) -> dict[str, Any]:
    """Paper V-A: an inclined ladder (60°) with 12 cm steps every 20 cm and two guardrails.
    The right foot goes on step 1 and the right hand on the right guardrail (both then fixed,
    bearing forces); the left foot is lifted, then goes on step 2 as a geometric contact whose
    ellipse radii are at least 40 % of the step's width (its depth, 12 cm). As a climb it
    has that one step of each foot (``steps`` 1)."""
    if steps > 1:
        raise InputError(
            "--steps",
            f"the inclined ladder climbs one step of each foot, not {steps}",
            "use --steps 1: right foot on step 1, left foot on step 2",
        )
    size = robot_size(robot)
    frames = _sole_frames(robot)
    alpha, rise, depth = math.radians(60.0), 0.2, 0.12
    width = max(0.5, 2 * (size.shoulder_half_width + RAIL_CLEARANCE))
    run = rise / math.tan(alpha)  # horizontal distance between steps
    # x0: where step 0 would be; step 1's front edge is LADDER_GAP in front of the toes
    x0 = 0.5 * size.sole_length + LADDER_GAP + 0.5 * depth - run
    n_steps = 2 * max(1, steps) + 2
    surfaces = _inclined_surfaces(size, alpha, (x0, run, rise), (depth, width), n_steps)
    stages = _inclined_stages(size, frames, (x0, run, rise), depth)
    return {
        "name": "ladder-inclined",
        "description": "inclined ladder (60°): left foot to step 2, ellipse radii >= 40 % of "
        "the step's width",
        "robot": robot_spec(robot),
        "mu": 0.7,
        "surfaces": surfaces,
        "obstacles": [],
        "initial": {"base": [0.0, 0.0, 0.0]},
        "options": LADDER_OPTIONS,
        "costs": CLIMB_COSTS,
        "stages": stages,
    }


# The vertical ladder, measured on HRP-2 (see ladder_vertical's notes): rungs every 25 cm,
# 2.5 cm thick, 25 cm in front of the toes at the start.
RUNG_SPACING = 0.25  # [m]
RUNG_THICKNESS = 0.025  # [m]
LADDER_STANDOFF = 0.25  # [m] from the toes at the start to the rungs' centre line
HAND_MU = 1.0  # a hand closed around a rung holds better than a sole on a plank
# [m] from the shoulders to the stiles. 10 cm while the proxies stood up to 10 cm out; with
# every pair avoided on proxies within 1 cm of HRP-2's meshes, its wrists met the stiles at
# 10 and 15 cm ('left hand on rung 5' infeasible), not at 20 cm
STILE_CLEARANCE = 0.2
# On a vertical ladder the body hangs behind the rungs (its knees cannot pass them): the hands
# pull it towards the ladder and the rung under the foot holds it back, both by friction along
# x. The default 4-face pyramid has its faces normal to x and y, so it grants only μ/√2 along x
# (where HRP-2's last stage failed, the foot and both hands were at that bound); 8 faces grant
# 0.92 μ.
LADDER_FRICTION: dict[str, Any] = {"model": "pyramid", "faces": 8}
RUNG_FOOT_Y = 0.0  # [m] the first foot's target on rung 1, right of the middle
# [m] the target of every later foot, this far left (left foot) or right (right foot) of the
# middle. Unguided, HRP-2's left foot landed 20 cm left of the middle on rung 2, and its climb
# (steps=1) failed at "left hand on rung 8" (its body's proxies against the ladder). With every
# pair avoided (issue 14) its climb (steps=2) failed at 'right foot on rung 3' with 5 cm (the
# shin against rungs 4 and 5, the chest held off the body), passed with 8 cm
CLIMB_FOOT_Y = 0.08


def _foot_on_rung(patch: str, k: int, geometric: bool, sole_width: float) -> dict[str, Any]:
    c: dict[str, Any] = {"robot_patch": patch, "surface": f"rung{k}"}
    if geometric:
        # paper V-B: the ellipse spans the foot's width (at least 80 % of it) and the rung's
        # thickness (at least 60 % of it)
        radii = [0.3 * RUNG_THICKNESS, 0.4 * sole_width]
        c.update({"type": "geometric", "min_radii": radii})
    else:
        c.update({"type": "support", "min_radii": [0.3 * RUNG_THICKNESS, 0.03]})
    return c


# Measured on HRP-2, each change alone makes ladder_vertical's last stage fail: the hands on
# rung 4 (below the shoulders) instead of 5; the right foot first, the hands after it; rungs
# every 30 cm (22 and 28 cm solve); the 4-face friction pyramid; no foothold task (the right
# foot then lands 21 cm right of the middle, and the robot cannot stand on it alone); a 4 cm
# minimum major radius instead of 80 % of the foot's width (which still solves with the
# standoff at 23, 27 or 30 cm). The demo solves with the standoff from 23 to 30 cm (not 20:
# the right foot's stage fails) and the foothold task's weight from 0.5 to 2.
@dataclass(frozen=True)
class _Rungs:
    """The stages of a vertical ladder whose rungs' centre line is at x = ``xl``."""

    size: RobotSize
    sole_frames: dict[str, str]
    xl: float

    def hand_on(self, h: str, k: int, keep: tuple[str, ...]) -> dict[str, Any]:
        hand = {"type": "support", "min_radii": [0.3 * RUNG_THICKNESS, 0.03], "mu": HAND_MU}
        return {
            "name": f"{h.replace('_', ' ')} on rung {k}",
            "contacts": [*_keep(*keep), {"robot_patch": h, "surface": f"rung{k}", **hand}],
        }

    def foothold(self, k: int, y: float) -> list[float]:
        """The sole frame's target on rung k: its toes on the rung's near half."""
        return [self.xl - 0.5 * self.size.sole_length - 0.01, y, k * RUNG_SPACING]

    def climb(self, hand_rung: int, steps: int) -> list[dict[str, Any]]:
        """The stages after the demo's: each foot ``steps`` times two rungs up, the hands
        first, ``hand_rung`` rungs above the foot that stays."""
        out = []
        feet = {"left_sole": 2, "right_sole": 1}
        hands = {"left_hand": hand_rung, "right_hand": hand_rung}
        for _ in range(max(0, steps)):
            for foot, other in (("right_sole", "left_sole"), ("left_sole", "right_sole")):
                for h, o in (("right_hand", "left_hand"), ("left_hand", "right_hand")):
                    hands[h] = feet[other] + hand_rung
                    out.append(self.hand_on(h, hands[h], ("left_sole", "right_sole", o)))
                feet[foot] += 2
                out.append(self.foot_on(foot, other, feet[foot]))
        return out

    def foot_on(self, foot: str, other: str, k: int) -> dict[str, Any]:
        y = CLIMB_FOOT_Y if foot == "left_sole" else -CLIMB_FOOT_Y
        return {
            "name": f"{foot.split('_')[0]} foot on rung {k}",
            "contacts": [
                *_keep(other, "right_hand", "left_hand"),
                _foot_on_rung(foot, k, True, self.size.sole_width),
            ],
            "tasks": [_foot_task(self.sole_frames[foot], self.foothold(k, y), FOOTHOLD_WEIGHT)],
        }


def ladder_vertical(robot: str, steps: int = 0) -> dict[str, Any]:
    """Paper V-B: a vertical ladder with 2.5 cm thick rungs every 25 cm. Standing in front of
    it, the robot puts both hands on the first rung at or above its shoulders, then its right
    foot on rung 1; the left foot goes on rung 2 as a geometric contact whose ellipse spans the
    foot's width and the rung's thickness, the right foot and both hands fixed. With
    ``steps`` = K > 0 the climb goes on: each foot climbs K more rungs, two at a time, after
    both hands moved up to ``hand_rung`` rungs above the other foot (one rung more than at the
    start: HRP-2 could not lift its right foot from rung 1 to 3 with its hands on rung 6,
    2.0x its wrist's limit, its knees held behind rung 4, but could with them on rung 7).
    Measured on HRP-2: see the note above."""
    size = robot_size(robot)
    sole_frames = _sole_frames(robot)
    xl = 0.5 * size.sole_length + LADDER_STANDOFF
    # the hands on the first rung at or above the shoulders (HRP-2: rung 5, 1.25 m)
    hand_rung = max(3, math.ceil(size.shoulder_height / RUNG_SPACING))
    n_rungs = hand_rung + 2 * max(0, steps) + 2
    # the stiles clear the shoulders by STILE_CLEARANCE (at least 45 cm between them)
    half_width = max(0.225, size.shoulder_half_width + STILE_CLEARANCE)
    surfaces = [GROUND]
    for k in range(1, n_rungs + 1):
        s = rect(f"rung{k}", [xl, 0.0, k * RUNG_SPACING], (RUNG_THICKNESS, 2 * half_width))
        s["thickness"] = RUNG_THICKNESS
        surfaces.append(s)
    obstacles = [
        box(f"{side}_stile", [xl, y, 1.6], [0.03, 0.04, 3.2])
        for side, y in (("left", half_width + 0.02), ("right", -half_width - 0.02))
    ]
    ladder = _Rungs(size, sole_frames, xl)
    hand_on, foothold, foot_on = ladder.hand_on, ladder.foothold, ladder.foot_on
    stages: list[dict[str, Any]] = [
        {"name": "stand", "contacts": _feet_on_ground(half_width=size.stance_half_width)},
        hand_on("right_hand", hand_rung, ("left_sole", "right_sole")),
        hand_on("left_hand", hand_rung, ("left_sole", "right_sole", "right_hand")),
        {
            "name": "right foot on rung 1",
            "contacts": [
                *_keep("left_sole", "right_hand", "left_hand"),
                _foot_on_rung("right_sole", 1, False, size.sole_width),
            ],
            "tasks": [
                _foot_task(sole_frames["right_sole"], foothold(1, -RUNG_FOOT_Y), FOOTHOLD_WEIGHT)
            ],
        },
        foot_on("left_sole", "right_sole", 2),
    ]
    stages += ladder.climb(hand_rung, steps)
    return {
        "name": "ladder-vertical",
        "description": "vertical ladder, 2.5 cm rungs: left foot to rung 2 (geometric) with "
        "the right foot and both hands fixed",
        "robot": robot_spec(robot),
        "mu": 0.7,
        "friction": LADDER_FRICTION,
        "surfaces": surfaces,
        "obstacles": obstacles,
        "initial": {"base": [0.0, 0.0, 0.0]},
        "options": LADDER_OPTIONS,
        "costs": CLIMB_COSTS,
        "stages": stages,
    }


@dataclass(frozen=True)
class SceneInfo:
    """A shipped scene: its builder, default robot, and demo/climb step counts."""

    build: Callable[[str, int], dict[str, Any]]
    robot: str
    demo_steps: int
    climb_steps: int | None  # None: not a climb
    description: str


SCENES: dict[str, SceneInfo] = {
    "stand-reach": SceneInfo(stand_reach, "talos", 1, None, "both feet fixed, hand at a target"),
    "wall-brace": SceneInfo(
        wall_brace, "talos", 1, None, "left hand braced on a wall, right hand reaching far"
    ),
    "ladder-inclined": SceneInfo(
        ladder_inclined, "hrp2", 1, 1, "paper V-A: inclined ladder, foot to step 2"
    ),
    "ladder-vertical": SceneInfo(
        ladder_vertical, "hrp2", 0, 2, "paper V-B: vertical ladder, 2.5 cm rungs"
    ),
    "stairs": SceneInfo(stairs, "atlas", 3, 4, "paper V-C: steps shorter than the foot"),
}


def scene(name: str, robot: str | None = None, steps: int | None = None) -> dict[str, Any]:
    """The sequence dict of a shipped scene (``steps`` None: its demo)."""
    if name not in SCENES:
        raise InputError("scene", f"unknown scene '{name}'", f"use one of: {', '.join(SCENES)}")
    info = SCENES[name]
    seq = info.build(robot or info.robot, info.demo_steps if steps is None else steps)
    if info.climb_steps is not None:  # a climb: each stage starts from the one before
        options = seq.get("options", {})
        seq["options"] = {**options, "solver": with_sequence_method(options.get("solver", {}))}
    return seq
