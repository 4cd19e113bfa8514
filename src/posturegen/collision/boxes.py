"""What collision avoidance avoids: its options (:class:`CollisionOptions`), the boxes of the
scene (obstacles, and the solids under support surfaces: :class:`EnvBox`, :func:`env_boxes`),
the user's excluded joint pairs, and sphere-box distances in numpy."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..model.robot import Robot
from ..terms.nlp import Instance
from .proxies import ProxyModel

BETA = 300.0  # [1/m] sharpness of the smooth max over box faces (the sphere-box rows)

MARGIN = 0.002  # [m] the default collision margin (see CollisionOptions)


TIGHTEN_STEP = 0.01  # [m] each retry's margin grows by this (CollisionOptions.tighten)


@dataclass(frozen=True)
class CollisionOptions:
    """What to avoid: self-collisions (``self_collision``), and always the scene's boxes and
    support surfaces; ``margin`` [m] between proxies; ``exclude`` pairs of joint names."""

    self_collision: bool = False
    # [m] the proxies contain the meshes and stand at most 1 cm outside them: the margin is
    # only a buffer on top. Measured on stand-reach (all pairs avoided): with 1 cm ATLAS and
    # G1 found no posture (IPOPT infeasible: the torso against the pelvis and the shoulders),
    # with 5 mm ATLAS neither, with 2 mm all five robots were verified
    margin: float = MARGIN
    exclude: tuple[tuple[str, str], ...] = ()
    environment: bool = True  # avoid the scene's obstacles and support surfaces
    activation: float = 0.05  # self pairs closer than margin + activation enter the program [m]
    # sphere-box pairs closer than margin + this enter the program [m]. Smaller than for self
    # pairs: fewer rows (talos-box-collision, in-process A/B, 4 rounds: 9.9 ms median at 3 cm,
    # 9.5 at 2 cm, 9.3 at 1 cm, 11.2 at 5 cm), but at 2 cm HRP-2's vertical ladder stage 'left
    # foot on rung 4' failed (tests/test_scenes.py). Self pairs: 13.7 ms at 5 cm, 13.5 at 3 cm,
    # 16.8 at 2 cm (talos-near-body-collision: the pairs met later force re-solves)
    environment_activation: float = 0.03
    max_rounds: int = 6  # active-set rounds
    # retries with a TIGHTEN_STEP larger margin when the mesh check fails. Rare but needed:
    # over the shipped climbs and plans, our seven scenes and the never-seen families (two
    # seeds, auto and IPOPT) 2026-12-05, none of at least 29 retries verified; but
    # examples/problems/frames_and_com.yaml (Talos' left fingertips 2.5 mm into its right
    # forearm at the first margin) verifies only through one (tests/test_examples.py)
    tighten: int = 2

    def largest_margin(self) -> float:
        """[m] the margin of the last retry."""
        return self.margin + TIGHTEN_STEP * self.tighten


@dataclass(frozen=True)
class EnvBox:
    """A box to avoid: placement, half sizes [m], joints allowed to touch it."""

    name: str
    T_world_box: pin.SE3
    half: np.ndarray  # (3,)
    allowed_joints: frozenset[int] = frozenset()

    def to_dict(self, model: pin.Model) -> dict[str, Any]:
        """Entry of the posture file's ``collision.boxes``."""
        return {
            "name": self.name,
            "placement": self.T_world_box.homogeneous.tolist(),
            "size": (2 * self.half).tolist(),
            "allowed_joints": sorted(model.names[j] for j in self.allowed_joints),
        }


def env_boxes(problem: Instance) -> list[EnvBox]:
    """The scene's obstacles, and its support surfaces as boxes under their bounding
    rectangle (``Surface.thickness`` deep), which the joints of the patches in contact with
    them may touch (none when the problem avoids self-collisions only)."""
    opts = problem.collision_options
    if opts is not None and not opts.environment:
        return []
    boxes = [EnvBox(o.name, o.T_world_box, np.asarray(o.size) / 2) for o in problem.scene.obstacles]
    for s in problem.scene.surfaces.values():
        allowed = frozenset(c.patch.joint_id for c in problem.contacts if c.surface is s)
        v = s.polygon.vertices
        lo, hi = v.min(axis=0), v.max(axis=0)
        t = s.thickness
        centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, -t / 2])
        half = np.array([(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, t / 2])
        boxes.append(
            EnvBox(
                f"surface:{s.name}", s.T_world_surface * pin.SE3(np.eye(3), centre), half, allowed
            )
        )
    return boxes


def excluded_joint_ids(robot: Robot, options: CollisionOptions) -> set[tuple[int, int]]:
    """The user's excluded pairs as sorted joint-id pairs (names of joints or frames)."""
    out = set()
    for a, b in options.exclude:
        ja, jb = (_joint_of(robot, n) for n in (a, b))
        out.add((min(ja, jb), max(ja, jb)))
    return out


def _joint_of(robot: Robot, name: str) -> int:
    model = robot.model
    if model.existJointName(name):
        return int(model.getJointId(name))
    if model.existFrame(name):
        return int(model.frames[model.getFrameId(name)].parentJoint)
    raise InputError(
        "options.collision_exclude",
        f"no joint or link named '{name}'",
        "name links or joints of the URDF",
    )


def box_distances(pm: ProxyModel, centers: np.ndarray, boxes: list[EnvBox]) -> np.ndarray:
    """(S, B) conservative distances max_k s_k - r of every sphere to every box [m]."""
    out = np.empty((len(centers), len(boxes)))
    for k, b in enumerate(boxes):
        local = (centers - b.T_world_box.translation) @ b.T_world_box.rotation
        out[:, k] = (np.abs(local) - b.half).max(axis=1) - pm.radii
    return out


def row_box_distances(
    pm: ProxyModel, centers: np.ndarray, boxes: list[EnvBox], below: float = np.inf
) -> np.ndarray:
    """(S, B) the sphere-box rows' own distances [m]: LSE_β(s) - log(6)/β - r over the six
    face distances s (:func:`posturegen.collision.soft_min.box_element`), up to log(6)/β below
    :func:`box_distances`. The active set compares these with the margin, so a pair left out
    of the rows is never one whose row would be violated (a foot fixed by the next stance
    where its row read 1.4 mm under the margin, though 3.6 mm clear by the faces' maximum,
    made ATLAS' stairs infeasible). A pair that is at least ``below`` [m] away by the lower
    bound max(s) - log(6)/β - r (LSE >= max) reads +inf: a comparison with a threshold <=
    ``below`` is the same, and the exponentials of the far spheres (most) are not taken."""
    out = np.full((len(centers), len(boxes)), np.inf)
    shift = np.log(6.0) / BETA
    for k, b in enumerate(boxes):
        local = (centers - b.T_world_box.translation) @ b.T_world_box.rotation  # (S, 3)
        excess = np.abs(local) - b.half  # (S, 3) the larger face distance of each axis
        smax = np.maximum(np.maximum(excess[:, 0], excess[:, 1]), excess[:, 2])  # (S,)
        near = np.flatnonzero(smax - shift - pm.radii < below)
        local, smax = local[near], smax[near]
        s = np.concatenate([local - b.half, -local - b.half], axis=1)  # (n, 6)
        lse = smax + np.log(np.exp(BETA * (s - smax[:, None])).sum(axis=1)) / BETA
        out[near, k] = lse - shift - pm.radii[near]
    return out
