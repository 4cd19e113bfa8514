"""The program's exact derivatives (CasADi AD, as IPOPT uses them) against central finite
differences, on seeded random points around the initial posture."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from posturegen.cli import _demo_dir
from posturegen.io.problem_file import load_problem, problem_from_dict

# floating contacts with every option that adds rows or costs: a support foot (forces on its
# ellipse's boundary) and a geometric foot (the paper's form, area maximized), both with yaw
# bounds, the second on a step shorter than the foot
FLOATING = {
    "robot": "talos",
    "surfaces": [
        {"name": "ground", "vertices": [[-1, -1], [1, -1], [1, 1], [-1, 1]]},
        {
            "name": "step",
            "position": [0.3, -0.1, 0.1],
            "rpy": [0, 0, 0.1],
            "vertices": [[-0.06, -0.3], [0.06, -0.3], [0.06, 0.3], [-0.06, 0.3]],
        },
    ],
    "contacts": [
        {
            "robot_patch": "left_sole",
            "surface": "ground",
            "type": "support",
            "yaw_range": [-0.3, 0.4],
        },
        {
            "robot_patch": "right_sole",
            "surface": "step",
            "type": "geometric",
            "formulation": "paper",
            "maximize_area": 1.0,
            "yaw_range": [-0.5, 0.2],
        },
    ],
}


# a support foot on a 2.5 cm rung: the scaled plane of sec. IV-F, whose CoP-margin row bounds
# the smallest eigenvalue of BᵀB (posturegen.terms.cop); the other foot fixed (polygon CoP rows);
# both with a grip (posturegen.terms.forces: the forces moved by it, as a hand's on a rail)
THIN = {
    "robot": "talos",
    "surfaces": [
        FLOATING["surfaces"][0],
        {
            "name": "rung",
            "position": [0.3, -0.1, 0.1],
            "vertices": [[-0.0125, -0.3], [0.0125, -0.3], [0.0125, 0.3], [-0.0125, 0.3]],
        },
    ],
    "contacts": [
        {
            "robot_patch": "left_sole",
            "surface": "ground",
            "type": "fixed",
            "position": [0, 0.1],
            "grip": 80.0,
        },
        {
            "robot_patch": "right_sole",
            "surface": "rung",
            "type": "support",
            "points": 6,
            "grip": 40.0,
        },
    ],
    "options": {"cop_margin": 0.004},
}


@pytest.fixture(scope="module", params=["stand-reach", "floating", "thin"])
def program(request):
    if request.param == "floating":
        problem = problem_from_dict(FLOATING)
    elif request.param == "thin":
        problem = problem_from_dict(THIN)
        assert problem.contacts[1].scaled
        assert {"contact.right_sole.cop", "contact.right_sole.cop_radius"} <= set(
            problem.constraint_counts()
        )
    else:
        problem = load_problem(_demo_dir() / "stand-reach.yaml")
    compiled = problem.compile()
    if request.param == "thin":
        assert {"contact.left_sole.grip", "contact.right_sole.grip"} <= set(compiled.p_index)
    x0, p, _, _ = problem.numeric(compiled)
    return compiled, x0, p


def _fd_jacobian(fun, x, h=1e-6):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_constraint_jacobian_and_cost_gradient(program, seed):
    compiled, x0, p = program
    rng = np.random.default_rng(seed)
    x = x0 + 0.2 * rng.normal(size=x0.size)
    xs = ca.MX.sym("x", x0.size)
    f, g = compiled.nlp(xs, p)
    jac = ca.Function("j", [xs], [ca.jacobian(g, xs), ca.gradient(f, xs)])
    J, grad = (np.array(v) for v in jac(x))

    def g_num(xv):
        return np.array(compiled.nlp(xv, p)[1]).ravel()

    def f_num(xv):
        return np.array(compiled.nlp(xv, p)[0]).ravel()

    J_fd = _fd_jacobian(g_num, x)
    np.testing.assert_allclose(J, J_fd, atol=1e-6 * max(1.0, np.abs(J).max()))
    np.testing.assert_allclose(grad.ravel(), _fd_jacobian(f_num, x).ravel(), atol=1e-6)


def test_lagrangian_hessian(program):
    compiled, x0, p = program
    rng = np.random.default_rng(3)
    x = x0 + 0.1 * rng.normal(size=x0.size)
    lam = rng.normal(size=compiled.n_g)
    xs = ca.MX.sym("x", x0.size)
    f, g = compiled.nlp(xs, p)
    lag = f + ca.dot(ca.DM(lam), g)
    grad_fn = ca.Function("gr", [xs], [ca.gradient(lag, xs)])
    hess_fn = ca.Function("h", [xs], [ca.hessian(lag, xs)[0]])
    H = np.array(hess_fn(x))
    H_fd = _fd_jacobian(lambda xv: np.array(grad_fn(xv)).ravel(), x, h=1e-5)
    np.testing.assert_allclose(H, H_fd, atol=1e-4 * max(1.0, np.abs(H).max()))


def test_block_derivatives_are_checked_when_declared():
    """A block's own derivatives must have its shape and be taken w.r.t. variables."""
    from posturegen.errors import SolveError
    from posturegen.solver.compile import _columns
    from posturegen.terms.nlp import NLP, BlockDerivatives

    nlp = NLP()
    x = nlp.variable("x", 3)
    lam = ca.SX.sym("lam", 2)
    good = BlockDerivatives(z=x[0:2], jacobian=ca.SX(2, 2), lam=lam, hessian=ca.SX(2, 2))
    nlp.constrain("ok", ca.vertcat(x[0] ** 2, x[1]), 0, 1, good)
    assert _columns(x[[2, 0]], x) == [2, 0]
    wrong = BlockDerivatives(z=x, jacobian=ca.SX(2, 2), lam=lam, hessian=ca.SX(3, 3))
    with pytest.raises(SolveError, match="Jacobian of the wrong shape"):
        nlp.constrain("wrong", ca.vertcat(x[0], x[1]), 0, 1, wrong)
    with pytest.raises(SolveError, match="variables of the program"):
        _columns(2 * x[0:1], x)
    with pytest.raises(SolveError, match="not variables"):
        _columns(ca.SX.sym("other", 1), x)
