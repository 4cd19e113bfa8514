"""A cached separated start, and a cached scan, are the ones their problem computes. Keyed on
q's joints alone (the base pose moves no self distance), the start cached by one problem
differed by ~1e-15 from the one a later problem with the same joints computed at its own base
pose (rounding moved a borderline pair); a stage of HRP-2's vertical ladder failed after plans
had filled the cache. The start is keyed on all of q; the scans search in the base's frame,
a function of the joints alone, and are keyed on the joints."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from posturegen import clear_caches
from posturegen.collision.active_set import ActiveSet
from posturegen.collision.separation import separated_start
from posturegen.io.problem_file import problem_from_dict
from posturegen.model.kinematics import at_origin
from posturegen.solver.problem import Program


def _problem(x: float, yaw: float):
    """HRP-2 standing at (x, 0) turned by yaw, self-collision avoided."""
    c, s = np.cos(yaw), np.sin(yaw)
    feet = [(0.0, 0.105), (0.0, -0.105)]
    world = [(x + c * a - s * b, s * a + c * b) for a, b in feet]
    return problem_from_dict(
        {
            "robot": "hrp2",
            "surfaces": [{"name": "ground", "vertices": [[-3, -3], [3, -3], [3, 3], [-3, 3]]}],
            "contacts": [
                {
                    "robot_patch": p,
                    "surface": "ground",
                    "type": "fixed",
                    "position": list(w),
                    "yaw": float(yaw),
                }
                for p, w in zip(("left_sole", "right_sole"), world, strict=True)
            ],
            "options": {"self_collision": True},
        }
    )


def test_a_cached_separated_start_is_the_one_its_problem_computes():
    """The same joints at three base poses: each start, computed after the others filled the
    cache, is bit for bit the one computed with an empty cache."""
    poses = ((0.0, 0.0), (1.3, 0.7), (-2.1, -2.5))

    def start(x: float, yaw: float) -> np.ndarray:
        program = Program.of(_problem(x, yaw))
        active = ActiveSet.of(program)
        q = program.q_init.copy()
        q[7:] = pin.neutral(program.robot.model)[7:] + 0.3  # joints bent: pairs to part
        q[7:] = np.clip(q[7:], program.robot.q_lower, program.robot.q_upper)
        joints = [c.patch.joint_id for c in program.contacts]
        out = separated_start(program.robot, active.pm, active.links, 0.005, q, joints)
        assert np.any(out != q[7:])  # it moved something
        return out

    alone = []
    for pose in poses:
        clear_caches()
        alone.append(start(*pose))
    clear_caches()
    after = [start(*pose) for pose in poses]  # each after the ones before it, cached
    for a, b in zip(alone, after, strict=True):
        assert np.array_equal(a, b)


def test_a_cached_scan_is_the_one_its_posture_computes():
    """The active set's scans are cached per joints: the same joints at three base poses,
    each scan's close pairs and distances, searched in the base's frame, are bit for bit the
    same whether computed with an empty cache or after the others filled it, and the same at
    every base pose (what makes the joints a key; from world centres they were ~1e-15
    apart); the scans' near and violated pairs too."""
    poses = ((0.0, 0.0), (1.3, 0.7), (-2.1, -2.5))

    def close(x: float, yaw: float) -> tuple[np.ndarray, np.ndarray, tuple[set, set]]:
        program = Program.of(_problem(x, yaw))
        active = ActiveSet.of(program)
        q = program.q_init.copy()
        q[7:] = pin.neutral(program.robot.model)[7:] + 0.3
        q[7:] = np.clip(q[7:], program.robot.q_lower, program.robot.q_upper)
        pin.forwardKinematics(active.model, active.data, at_origin(q))
        centers = active.pm.centers_world(active.model, active.data)
        slack = np.full(len(active.pm.joint_pairs), 0.05)
        found = active._cached_close(q, centers, slack)
        scan = active.scan(q, 0.005)
        return np.stack([found.i, found.j]), found.d.copy(), (scan.near_self, scan.violated_self)

    alone = []
    for pose in poses:
        clear_caches()
        alone.append(close(*pose))
    clear_caches()
    after = [close(*pose) for pose in poses]
    assert len(alone[0][1]) > 0 and alone[0][2][0]  # pairs were found
    for (pairs_a, d_a, scan_a), (pairs_b, d_b, scan_b) in zip(alone, after, strict=True):
        assert np.array_equal(pairs_a, pairs_b) and np.array_equal(d_a, d_b)
        assert scan_a == scan_b
        assert np.array_equal(pairs_a, alone[0][0]) and np.array_equal(d_a, alone[0][1])
