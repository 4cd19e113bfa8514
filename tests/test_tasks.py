"""The task library (posturegen.terms.tasks): every task type is met by a solved posture,
re-checked by verify (which rejects a tampered value), its error's Jacobian matches finite
differences of Pinocchio's, and a task of the user's own works like a built-in one."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from posturegen import problem_from_dict, solve
from posturegen.errors import InputError
from posturegen.model.kinematics import CasadiKinematics
from posturegen.model.robot import load_bundled
from posturegen.terms.nlp import NLP, BuildContext
from posturegen.terms.tasks import (
    Field,
    Frames,
    NumericFrames,
    SymbolicFrames,
    Task,
    read_task,
    register_task,
    task_types,
)
from posturegen.verify import verify_posture
from tests.stances import talos_on_ground

STAND = talos_on_ground(self_collision=False)
HAND = "gripper_right_base_link"
LEFT = "gripper_left_base_link"

# one reachable entry per task type, and how to tamper with its written entry so that the
# posture no longer meets it
ENTRIES = {
    "position": ({"frame": HAND, "target": [0.4, -0.35, 0.95]}, ("target", 0, 0.01)),
    "pose": (
        {"frame": HAND, "target": [0.4, -0.35, 0.95], "rpy": [0.2, 0.6, 2.9]},
        ("rpy", 1, 0.02),
    ),
    "orientation": ({"frame": HAND, "rpy": [0.3, 0.6, 2.8]}, ("rpy", 2, 0.05)),
    "axis": ({"frame": HAND, "axis": [0, 0, 1], "direction": [1, 0, 0]}, ("direction", 1, 0.2)),
    "gaze": ({"frame": "rgbd_optical_frame", "axis": [0, 0, 1], "target": [1.0, -0.4, 0.6]},
             ("target", 2, 0.1)),
    "region": ({"frame": HAND, "min": [0.35, -0.5, 1.1], "max": [0.5, -0.3, 1.3]},
               ("max", 2, -0.25)),
    "relative": ({"frame": LEFT, "reference": HAND, "target": [0.0, 0.3, 0.0]},
                 ("target", 1, 0.02)),
    "distance": ({"frame": LEFT, "other": HAND, "range": [0.1, 0.15]}, ("range", 1, -0.1)),
    "com": ({"polygon": [[-0.02, -0.06], [0.06, -0.06], [0.06, 0.06], [-0.02, 0.06]],
             "margin": 0.01}, ("margin", None, 0.2)),
    "joints": ({"values": {"torso_2_joint": 0.3, "head_1_joint": [0.2, 0.4]}},
               ("values", "torso_2_joint", 0.05)),
}  # fmt: skip


def _problem(entry: dict, kind: str):
    data = copy.deepcopy(STAND)
    data["tasks"] = [{"type": kind, **entry}]
    return problem_from_dict(data)


def test_every_registered_task_has_a_test_entry():
    assert set(task_types()) >= set(ENTRIES)
    assert set(ENTRIES) >= {
        k for k, c in task_types().items() if c.__module__.startswith("posturegen")
    }


@pytest.mark.parametrize("kind", sorted(ENTRIES))
def test_a_hard_task_is_met_verified_and_a_tampered_value_rejected(kind):
    entry, (key, where, delta) = ENTRIES[kind]
    problem = _problem(entry, kind)
    result = solve(problem)
    assert result.success, result.message
    posture = result.posture
    report = verify_posture(posture, problem.robot.model)
    assert report.ok, report
    written = posture["tasks"][0]
    assert written["type"] == kind
    # the re-check reads the written entry back as the same task
    task = read_task(written, "tasks[0]", 0)
    data = pin.Data(problem.robot.model)
    pin.framesForwardKinematics(problem.robot.model, data, result.q)
    assert max(task.violation(NumericFrames(problem.robot.model, data, result.q)).values()) < 1e-6
    tampered = copy.deepcopy(posture)
    value = tampered["tasks"][0][key]
    if where is None:
        tampered["tasks"][0][key] = value + delta
    else:
        value[where] = value[where] + delta
    bad = verify_posture(tampered, problem.robot.model)
    failed = [c.name for c in bad.checks if not c.ok]
    assert failed == ["tasks"], bad


def _symbolic(robot, task: Task):
    """The task's error e(q) (stacked blocks) and its Jacobian wrt q as one CasADi Function of
    (q, parameters)."""
    kin = CasadiKinematics(robot.model)
    q = ca.SX.sym("q", robot.model.nq)
    ctx = BuildContext(robot=robot, nlp=NLP(), kin=kin, state=kin.forward_q(q), joints=q[7:])
    e = ca.vertcat(*task.errors(SymbolicFrames(ctx, task.name)).values())
    p = ca.vertcat(*ctx.nlp.p.values())
    return ca.Function("e", [q, p], [e, ca.jacobian(e, q)]), list(ctx.nlp.p)


def _numeric(robot, task: Task, q: np.ndarray) -> np.ndarray:
    data = pin.Data(robot.model)
    pin.framesForwardKinematics(robot.model, data, q)
    blocks = task.errors(NumericFrames(robot.model, data, q))
    return np.concatenate(
        [np.atleast_1d(np.asarray(b, dtype=float)).ravel() for b in blocks.values()]
    )


@pytest.mark.parametrize("kind", sorted(ENTRIES))
def test_a_task_error_equals_pinocchio_and_its_jacobian_finite_differences(kind):
    """At seeded random configurations: the program's error equals Pinocchio's to 1e-9, and
    its Jacobian in the base position and the joints equals central differences of it."""
    robot = load_bundled("talos")
    problem = _problem(ENTRIES[kind][0], kind)
    task = problem.tasks[0]
    fn, names = _symbolic(robot, task)
    params = task.parameters(problem)
    p = np.concatenate([np.ravel(params[n], order="F") for n in names]) if names else np.zeros(0)
    rng = np.random.default_rng(7)
    pin.seed(7)  # pinocchio's randomConfiguration draws from its own generator
    model = robot.model
    for _ in range(3):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        q[0:3] = rng.uniform(-0.5, 0.5, 3)
        e, J = fn(q, p)
        np.testing.assert_allclose(np.array(e).ravel(), _numeric(robot, task, q), atol=1e-9)
        J = np.array(J)
        h = 1e-6
        for i in [0, 1, 2, *rng.choice(np.arange(7, model.nq), 8, replace=False)]:
            dq = np.zeros(model.nq)
            dq[i] = h
            fd = (_numeric(robot, task, q + dq) - _numeric(robot, task, q - dq)) / (2 * h)
            np.testing.assert_allclose(J[:, i], fd, atol=1e-6, err_msg=f"{kind}: q[{i}]")


def test_a_soft_task_pulls_and_a_new_target_reuses_the_program():
    """com height, soft: the optimum moves toward the target; a second target solves with the
    same compiled structure (its value is a parameter)."""
    free = solve(problem_from_dict(STAND))
    assert free.success
    data = pin.Data(load_bundled("talos").model)
    z0 = pin.centerOfMass(load_bundled("talos").model, data, free.q)[2]
    entry = {"height": float(z0) - 0.1, "weight": 10.0}
    soft = solve(_problem(entry, "com"))
    z1 = pin.centerOfMass(load_bundled("talos").model, data, soft.q)[2]
    assert soft.success and z1 < z0 - 0.02
    again = solve(_problem({"height": float(z0) - 0.15, "weight": 10.0}, "com"))
    assert again.success and again.build_time_s < 0.05
    z2 = pin.centerOfMass(load_bundled("talos").model, data, again.q)[2]
    assert z2 < z1


BAD = [
    ({"type": "gaz", "frame": HAND, "target": [1, 0, 1]}, r"tasks\[0\]\.type.*did you mean gaze"),
    ({"type": "axis", "frame": HAND, "axis": [0, 0, 1]}, r"tasks\[0\]: needs direction or"),
    (
        {"type": "axis", "frame": HAND, "axis": [0, 0, 0], "normal": [0, 0, 1]},
        r"tasks\[0\]\.axis: is the zero vector",
    ),
    (
        {"type": "joints", "values": {"torso_3_joint": 0.1}},
        r"tasks\[0\]\.values\.torso_3_joint.*did you mean",
    ),
    ({"type": "distance", "frame": HAND, "other": "hand", "distance": 0.2}, r"tasks\[0\]\.other"),
    ({"type": "com", "height": 0.8, "target": [0, 0, 0.8]}, r"needs one of target, height"),
    ({"type": "region", "frame": HAND, "min": [0, 0, 1], "max": [1, 1, 0]}, r"tasks\[0\]\.min"),
]


@pytest.mark.parametrize(("entry", "message"), BAD)
def test_bad_task_entries_are_one_line_errors(entry, message):
    data = copy.deepcopy(STAND)
    data["tasks"] = [entry]
    with pytest.raises(InputError, match=message):
        problem_from_dict(data)


def test_a_blocking_task_is_named_by_diagnose():
    from posturegen import diagnose

    problem = _problem({"values": {"torso_2_joint": 3.0}}, "joints")
    result = solve(problem)
    assert not result.success
    diagnosed = diagnose(problem, result)
    assert "task 0" in diagnosed.diagnosis and "torso_2_joint" in diagnosed.diagnosis


@register_task
@dataclass
class _HandsLevel(Task):
    """Both grippers at the same height (a user's task, registered from a test)."""

    kind: ClassVar[str] = "test_hands_level"
    fields: ClassVar[dict[str, Field]] = {
        "left": Field("frame", "one hand"),
        "right": Field("frame", "the other"),
    }
    left: str
    right: str

    def subject(self) -> str:
        return "hands"

    def errors(self, f: Frames) -> dict[str, object]:
        return {"level": f.position(self.left)[2] - f.position(self.right)[2]}


def test_a_task_of_ones_own_is_solved_written_and_verified():
    data = copy.deepcopy(STAND)
    data["tasks"] = [
        {"type": "position", "frame": HAND, "target": [0.4, -0.35, 1.1]},
        {"type": "test_hands_level", "left": LEFT, "right": HAND},
    ]
    problem = problem_from_dict(data)
    result = solve(problem)
    assert result.success
    posture = result.posture
    assert posture["tasks"][1] == {
        "type": "test_hands_level",
        "left": LEFT,
        "right": HAND,
        "weight": None,
    }
    assert verify_posture(posture, problem.robot.model).ok
    posture["tasks"][1]["right"] = "gripper_right_base_link_typo"
    assert not verify_posture(posture, problem.robot.model).ok


def test_a_kind_registered_twice_by_another_class_is_an_error():
    with pytest.raises(InputError, match="'position' is registered already"):

        @register_task
        @dataclass
        class Other(Task):
            kind: ClassVar[str] = "position"

    with pytest.raises(InputError, match=r"no attribute for the keys \['frame'\]"):

        @register_task
        @dataclass
        class NoFrame(Task):
            kind: ClassVar[str] = "test_no_frame"
            fields: ClassVar[dict[str, Field]] = {"frame": Field("frame", "a frame")}

    assert "test_no_frame" not in task_types()


def test_a_soft_range_of_zero_and_one_of_another_value_share_a_program_and_both_pull():
    """Which blocks are ranges is structure, not their values: joints at 0, then at 0.3,
    soft, reuse one program and each pulls its joint toward its own value."""
    model = load_bundled("talos").model
    index = model.joints[model.getJointId("torso_2_joint")].idx_q
    first = solve(_problem({"values": {"torso_2_joint": 0.0}, "weight": 100.0}, "joints"))
    second = solve(_problem({"values": {"torso_2_joint": 0.3}, "weight": 100.0}, "joints"))
    assert first.success and second.success
    assert abs(first.q[index]) < 0.02 and abs(second.q[index] - 0.3) < 0.02
    assert second.build_time_s < 0.05  # the program of the first
