"""Problems written for a peer solver (``tools/drake_peer.py``: Drake in its own virtual
environment, not a dependency of posturegen): each problem as plain JSON, the robot's URDF and
meshes by path, every pose a 4×4 matrix, every link by its URDF name, so that the peer
formulates the same program (fixed feet bearing forces at their polygons' vertices within
friction pyramids, static equilibrium with torque limits, the hand's target, the avoided link
pairs and boxes) without posturegen.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..collision.active_set import ActiveSet
from ..errors import InputError
from ..solver.problem import Problem


def _link(model: pin.Model, joint: int) -> str:
    """The URDF link whose frame is joint ``joint``'s (the body it carries)."""
    for frame in model.frames:
        if frame.parentJoint == joint and frame.type == pin.FrameType.BODY:
            if np.allclose(frame.placement.homogeneous, np.eye(4)):
                return str(frame.name)
    raise ValueError(f"joint '{model.names[joint]}' carries no body at its frame")


def _pose(T: pin.SE3) -> list[list[float]]:
    return np.asarray(T.homogeneous).tolist()


def _contacts(problem: Problem) -> list[dict[str, Any]]:
    """Each fixed contact: its link's pose, its force points in the link, the surface's normal
    and its friction."""
    model, out = problem.robot.model, []
    for c in problem.contacts:
        if not c.fixed_in_place:
            raise ValueError(f"contact '{c.name}': only fixed contacts are exported")
        out.append(
            {
                "name": c.name,
                "link": _link(model, c.patch.joint_id),
                "T_world_link": _pose(c.T_world_target * c.patch.T_joint_patch.inverse()),
                "points_link": np.asarray(c.points_joint).tolist(),  # force points (k, 3)
                # the surface's normal, into the robot: a force on the robot f has
                # f·n >= 0 and |f - (f·n)n| <= mu·(f·n) (a pyramid of friction_faces faces)
                "normal_world": (-np.asarray(c.T_world_target.rotation[:, 2])).tolist(),
                # the pyramid's first face direction: the surface's x axis (the forces are
                # W·R_surface·φ with φ in the pyramid)
                "tangent_world": np.asarray(c.surface.T_world_surface.rotation[:, 0]).tolist(),
                "mu": float(c.mu),
                "friction_faces": int(c.friction.faces),
                "cop_margin": float(c.cop_margin),  # [m] the centre of pressure inside the polygon
            }
        )
    return out


def _avoided(problem: Problem) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The link pairs posturegen avoids, each with how far apart it holds them [m], and the
    boxes with the links allowed to touch them."""
    opts, model = problem.collision_options, problem.robot.model
    if opts is None:
        return [], []
    active = ActiveSet.of(problem)
    hold = np.minimum(active.pm.pair_clearance(opts.margin), active.caps)
    pairs = []
    for k in active.links:
        a, b = (int(j) for j in active.pm.joint_pairs[k])
        pairs.append({"links": [_link(model, a), _link(model, b)], "hold": float(hold[k])})
    boxes = [
        {
            "name": box.name,
            "T_world_box": _pose(box.T_world_box),
            "half": np.asarray(box.half).tolist(),
            "allowed_links": sorted(_link(model, j) for j in box.allowed_joints),
        }
        for box in active.boxes
    ]
    return pairs, boxes


def export_problem(problem: Problem, family: str = "", index: int = 0) -> dict[str, Any]:
    """The problem as plain data (see the module doc); only fixed contacts and position tasks
    (the planner families' problems)."""
    robot, model = problem.robot, problem.robot.model
    tasks = []
    for t in problem.tasks:
        if t.kind != "position" or t.rpy is not None or t.weight is not None:
            raise InputError("tasks", f"{t.kind} task: the peer exports hard positions only", "")
        frame = model.frames[model.getFrameId(t.frame)]
        tasks.append(
            {
                "link": _link(model, int(frame.parentJoint)),
                "point_link": np.asarray(frame.placement.translation).tolist(),
                "target_world": np.asarray(t.target).tolist(),
            }
        )
    pairs, boxes = _avoided(problem)
    opts = problem.collision_options
    return {
        "family": family,
        "index": index,
        "robot": robot.name,
        "urdf": str(robot.urdf),
        "package_dirs": [str(p) for p in robot.package_dirs],
        "q_init": np.asarray(problem.q_init).tolist(),  # Pinocchio: xyz, quaternion xyzw, joints
        "joints": [str(model.names[j]) for j in range(2, model.njoints)],  # actuated, q's order
        "effort": np.asarray(model.effortLimit[6:]).tolist(),  # [N·m] per actuated joint
        "torque_limit_scale": float(problem.torque_limit_scale),
        "gravity": np.asarray(model.gravity.linear).tolist(),
        "mass": float(sum(i.mass for i in model.inertias)),
        "contacts": _contacts(problem),
        "tasks": tasks,
        "margin": None if opts is None else float(opts.margin),
        "self_pairs": pairs,  # the link pairs posturegen avoids, each held 'hold' [m] apart
        "boxes": boxes,  # boxes avoided by every link but their allowed ones
        "cost": "sum of squared joint offsets from q_init (posturegen: posture cost)",
    }


def write_problems(path: str | Path, items: list[dict[str, Any]]) -> Path:
    """Write exported problems, one JSON object per line."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("".join(json.dumps(item) + "\n" for item in items))
    return out
