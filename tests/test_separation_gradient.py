"""The separated start's sphere-pair distance gradient against central finite differences, on
seeded random configurations of Talos, with one step's Jacobians shared by every pair (as
:func:`posturegen.collision.separation._shortfalls` shares them)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from posturegen.collision.proxies import proxy_model
from posturegen.collision.separation import _pair_gradient
from posturegen.model.robot import load_robot

EPS = 1e-6  # [rad, m] the finite-difference step along each velocity coordinate


def _distance(model: pin.Model, data: pin.Data, pm, q: np.ndarray, i: int, j: int) -> float:
    """|c_i - c_j| [m] of spheres i and j at q (their radii are constants of the gradient)."""
    pin.forwardKinematics(model, data, q)
    centers = pm.centers_world(model, data)
    return float(np.linalg.norm(centers[i] - centers[j]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pair_gradient_matches_finite_differences(seed: int) -> None:
    robot = load_robot("talos")
    model, data = robot.model, robot.model.createData()
    pm = proxy_model(robot)
    rng = np.random.default_rng(seed)
    pin.seed(seed)  # pinocchio's randomConfiguration draws from its own generator
    q = pin.randomConfiguration(model)
    q[:3] = rng.uniform(-1.0, 1.0, 3)
    pin.forwardKinematics(model, data, q)
    pin.computeJointJacobians(model, data, q)
    centers = pm.centers_world(model, data)
    spheres = rng.choice(len(pm.spheres), size=(8, 2), replace=False)
    jacobians: dict[int, np.ndarray] = {}  # shared by the pairs, as within one step
    for i, j in spheres:
        i, j = int(i), int(j)
        if pm.spheres[i].joint_id == pm.spheres[j].joint_id:
            continue  # one rigid body: its distance is constant
        grad = _pair_gradient(model, data, pm, centers, (i, j), jacobians)  # (nv,)
        fd = np.zeros(model.nv)
        scratch = model.createData()
        for k in range(model.nv):
            step = np.zeros(model.nv)
            step[k] = EPS
            up = _distance(model, scratch, pm, pin.integrate(model, q, step), i, j)
            down = _distance(model, scratch, pm, pin.integrate(model, q, -step), i, j)
            fd[k] = (up - down) / (2 * EPS)
        np.testing.assert_allclose(grad, fd, atol=1e-6, err_msg=f"spheres {i}, {j}")
    assert jacobians, "no pair of distinct links was drawn"
