"""Fixed contacts at any heading: the orientation rows admit only the requested rotation, and
the initial posture is placed on the fixed contacts when its base is not given."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen import problem_from_dict, solve
from posturegen.io.placement import fit_yaw_translation

GROUND = {"name": "ground", "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]}
YAWS = np.linspace(-np.pi, np.pi, 17)  # steps of π/8


def feet_at(robot: str, yaw: float, half_width: float = 0.1, options: dict | None = None) -> dict:
    """Both soles fixed side by side about the origin, the stance turned by ``yaw``."""
    side = np.array([-np.sin(yaw), np.cos(yaw)]) * half_width
    return {
        "robot": robot,
        "surfaces": [dict(GROUND)],
        "contacts": [
            {
                "robot_patch": "left_sole",
                "surface": "ground",
                "type": "fixed",
                "position": side.tolist(),
                "yaw": float(yaw),
            },
            {
                "robot_patch": "right_sole",
                "surface": "ground",
                "type": "fixed",
                "position": (-side).tolist(),
                "yaw": float(yaw),
            },
        ],
        "options": options or {},
    }


def _base_yaw(q: np.ndarray) -> float:
    R = pin.Quaternion(q[3:7]).normalized().matrix()
    return float(np.arctan2(R[1, 0], R[0, 0]))


@pytest.mark.parametrize("robot", ["talos", "hrp2"])
def test_fixed_feet_at_every_heading(robot):
    """Every yaw in [-π, π] in steps of π/8: verified (verify checks each fixed pose to 1e-6),
    the base turned with the stance."""
    for yaw in YAWS:
        r = solve(problem_from_dict(feet_at(robot, yaw)))
        assert r.success, f"yaw {yaw:.4f}: {r.message}"
        turn = np.angle(np.exp(1j * (_base_yaw(r.q) - yaw)))
        assert abs(turn) < 0.3, f"yaw {yaw:.4f}: the base faces {_base_yaw(r.q):.3f}"


def test_orientation_rows_reject_the_patch_turned_by_pi(talos):
    """The posture of feet fixed at yaw 0 meets the position rows and the three orientation
    equalities of the same feet fixed at yaw π (E = Rz(π)); the branch row rejects it."""
    r = solve(problem_from_dict(feet_at("talos", 0.0)))
    assert r.success, r.message
    # the same soles' positions at yaw π, started from that posture (x0 is the posture)
    start = {"initial": r.q.tolist()}
    flipped = problem_from_dict(feet_at("talos", np.pi, half_width=-0.1, options=start))
    compiled = flipped.compile()
    x, p, lbg, _ = flipped.numeric(compiled)
    g = np.array(compiled.nlp(x, p)[1]).ravel()
    for name in ("left_sole", "right_sole"):
        for block in ("position", "orientation"):
            rows = g[compiled.g_index[f"contact.{name}.{block}"]]
            np.testing.assert_allclose(rows, 0.0, atol=1e-6)
        branch = g[compiled.g_index[f"contact.{name}.orientation_branch"]]
        assert branch[0] == pytest.approx(-1.0, abs=1e-6)  # trace of Rz(π)
        assert branch[0] < lbg[compiled.g_index[f"contact.{name}.orientation_branch"]][0]


def test_the_initial_base_is_placed_only_when_not_given(talos):
    yaw = 2.75
    placed = problem_from_dict(feet_at("talos", yaw, options={"initial": "half_sitting"}))
    assert _base_yaw(placed.q_init) == pytest.approx(yaw, abs=1e-3)
    np.testing.assert_allclose(placed.q_init[7:], talos.q_init[7:])
    # the placed posture's soles are on their targets, to the default posture's own
    # irregularity (half-sitting's soles are rolled by 1.7 mrad)
    width = _sole_half_width(talos)
    exact = problem_from_dict(feet_at("talos", yaw, half_width=width))
    data = talos.model.createData()
    pin.framesForwardKinematics(talos.model, data, exact.q_init)
    for c in exact.contacts:
        T = data.oMf[c.patch.frame_id] * c.patch.T_frame_patch
        assert np.allclose(T.homogeneous, c.T_world_target.homogeneous, atol=2e-3)
    given_q = talos.q_init.tolist()
    explicit = problem_from_dict(feet_at("talos", yaw, options={"initial": given_q}))
    np.testing.assert_array_equal(explicit.q_init, given_q)


def _sole_half_width(robot) -> float:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_init)
    return float(data.oMf[robot.patch("left_sole").frame_id].translation[1])


@settings(max_examples=50, deadline=None)
@given(
    points=st.lists(
        st.tuples(*[st.floats(-1, 1) for _ in range(3)]), min_size=3, max_size=12
    ).filter(lambda p: np.ptp(np.array(p)[:, :2], axis=0).min() > 0.1),
    yaw=st.floats(-np.pi + 1e-3, np.pi - 1e-3),
    t=st.tuples(*[st.floats(-2, 2) for _ in range(3)]),
)
def test_fit_yaw_translation_recovers_a_rigid_motion(points, yaw, t):
    a = np.array(points)
    b = a @ pin.utils.rotate("z", yaw).T + np.array(t)
    fit_yaw, fit_t = fit_yaw_translation(a, b)
    assert fit_yaw == pytest.approx(yaw, abs=1e-9)
    np.testing.assert_allclose(fit_t, t, atol=1e-9)


def test_the_placed_height_is_that_of_the_surfaces_stood_on(talos):
    """Feet fixed on a 0.3 m platform lift the placed posture by 0.3 m; a hand fixed high on
    a wall does not lift the feet off the ground."""
    platform = feet_at("talos", 0.0)
    platform["surfaces"][0]["position"] = [0.0, 0.0, 0.3]
    lifted = problem_from_dict(platform)
    assert lifted.q_init[2] == pytest.approx(talos.q_init[2] + 0.3, abs=1e-5)  # sole origins
    braced = feet_at("talos", 0.0)
    braced["surfaces"].append(
        {
            "name": "wall",
            "position": [0.1, 0.6, 1.4],
            "rpy": [np.pi / 2, 0.0, 0.0],  # facing -y, towards the robot
            "vertices": [[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]],
        }
    )
    braced["contacts"].append(
        {"robot_patch": "left_hand", "surface": "wall", "type": "fixed", "position": [0, 0]}
    )
    problem = problem_from_dict(braced)
    assert problem.q_init[2] == pytest.approx(talos.q_init[2], abs=1e-5)
