"""The CasADi kinematics against Pinocchio's own numbers, to 1e-9, on drawn postures (and seeded
random ones)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings

from posturegen.model.kinematics import CasadiKinematics, so3_exp
from tests.strategies import postures

TOL = 1e-9


def _models():
    from posturegen.model.robot import load_bundled

    return {name: load_bundled(name).model for name in ("talos", "hrp2", "atlas")}


MODELS = _models()


def _random_q(model: pin.Model, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -3.0)
    hi = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, 3.0)
    q = rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0))
    q[0:3] = rng.normal(size=3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    return q


@pytest.fixture(scope="module", params=sorted(MODELS))
def setup(request):
    model = MODELS[request.param]
    kin = CasadiKinematics(model)
    q = ca.SX.sym("q", model.nq)
    state = kin.forward_q(q)
    frames = list(range(1, model.nframes))
    outs = []
    for f in frames:
        R, p = kin.frame_placement(state, f)
        outs += [R, p, kin.frame_jacobian(state, f)]
    fn = ca.Function("kin", [q], [*outs, kin.generalized_gravity(state), kin.com_world(state)])
    return model, kin, fn, frames


def test_frames_jacobians_gravity_match_pinocchio(setup):
    model, _, fn, frames = setup
    data = model.createData()

    @settings(max_examples=5, deadline=None, database=None, derandomize=True)
    @given(q=postures(model))
    def check(q):
        out = [np.array(v) for v in fn(q)]
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, f in enumerate(frames):
            R, p, J = out[3 * k], out[3 * k + 1].ravel(), out[3 * k + 2]
            np.testing.assert_allclose(R, data.oMf[f].rotation, atol=TOL, rtol=0)
            np.testing.assert_allclose(p, data.oMf[f].translation, atol=TOL, rtol=0)
            Jp = pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)
            np.testing.assert_allclose(J, Jp, atol=TOL, rtol=0, err_msg=model.frames[f].name)
        g = pin.computeGeneralizedGravity(model, data, q)
        np.testing.assert_allclose(out[-2].ravel(), g, atol=TOL * max(1.0, np.abs(g).max()), rtol=0)
        np.testing.assert_allclose(out[-1].ravel(), pin.centerOfMass(model, data, q), atol=TOL)

    check()


def test_static_terms_equal_gravity_minus_jacobian_transpose_forces(setup):
    """joint rows of g(q) - Σ Jᵀf, and the base resultant, against Pinocchio Jacobians."""
    model, kin, _, _ = setup
    data = model.createData()
    rng = np.random.default_rng(7)
    q = _random_q(model, rng)
    joints = [int(j) for j in rng.choice(np.arange(2, model.njoints), size=3, replace=False)]
    pts_local = rng.normal(size=(3, 3)) * 0.1
    forces = rng.normal(size=(3, 3)) * 100
    qs = ca.SX.sym("q", model.nq)
    st = kin.forward_q(qs)
    cps = [
        (int(j), kin.point_world(st, int(j), pts_local[i]), ca.DM(forces[i]))
        for i, j in enumerate(joints)
    ]
    F, N, tau = kin.static_wrench_terms(st, cps)
    F, N, tau = (np.array(v).ravel() for v in ca.Function("s", [qs], [F, N, tau])(q))
    pin.computeJointJacobians(model, data, q)
    expected = pin.computeGeneralizedGravity(model, data, q).copy()
    total_f = np.zeros(3)
    for i, j in enumerate(joints):
        M = data.oMi[j]
        pw = M.act(pts_local[i])
        J = pin.getJointJacobian(model, data, int(j), pin.LOCAL_WORLD_ALIGNED)
        expected -= J[:3].T @ forces[i] + J[3:].T @ np.cross(pw - M.translation, forces[i])
        total_f += forces[i]
    np.testing.assert_allclose(tau, expected[6:], atol=1e-8)
    mass = pin.computeTotalMass(model)
    np.testing.assert_allclose(F, mass * model.gravity.linear + total_f, atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_so3_exp_series_matches_pinocchio(seed):
    rng = np.random.default_rng(seed)
    for w in (
        rng.normal(size=3),
        1e-9 * rng.normal(size=3),
        np.zeros(3),
        3.0 * rng.normal(size=3) / np.sqrt(3),
    ):
        if np.linalg.norm(w) > np.pi:
            w = w / np.linalg.norm(w) * np.pi
        R = np.array(ca.evalf(so3_exp(ca.DM(w))))
        np.testing.assert_allclose(R, pin.exp3(w), atol=1e-13)


def test_unsupported_joint_type_is_a_clear_model_error():
    from posturegen.errors import ModelError

    model = pin.Model()
    ff = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "root")
    model.addJoint(ff, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    with pytest.raises(ModelError, match="ball"):
        CasadiKinematics(model)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_twist_jacobians_are_the_derivatives_of_the_placements(name):
    """[∂p_i/∂z; ω_i] with ω_i = vee(∂R_i/∂z_m R_iᵀ), z = (p, w, qj) or qj, to 1e-9."""
    model = MODELS[name]
    kin = CasadiKinematics(model)
    p, w, qj = ca.SX.sym("p", 3), ca.SX.sym("w", 3), ca.SX.sym("qj", kin.nj)
    R0 = ca.DM(pin.utils.rpyToMatrix(0.3, -0.2, 1.1))
    world = kin.forward(p, R0 @ so3_exp(w), qj)
    local = kin.forward(ca.SX.zeros(3), ca.SX.eye(3), qj)
    joints = list(range(1, model.njoints))
    rng = np.random.default_rng(7)
    for state, z, base in ((world, ca.vertcat(p, w, qj), w), (local, qj, None)):
        J = kin.twist_jacobians(state, joints, base)
        outs = []
        for i in joints:
            dR = ca.jacobian(ca.vec(state.R[i]), z)
            omega = []
            for m in range(z.shape[0]):
                S = ca.reshape(dR[:, m], 3, 3) @ state.R[i].T
                omega.append(ca.vertcat(S[2, 1], S[0, 2], S[1, 0]))
            outs += [J[i], ca.vertcat(ca.jacobian(state.p[i], z), ca.horzcat(*omega))]
        fn = ca.Function("twists", [z], outs)
        for _ in range(3):
            zv = rng.uniform(-1.0, 1.0, z.shape[0])
            out = [np.array(v) for v in fn(zv)]
            for mine, reference in zip(out[0::2], out[1::2], strict=True):
                np.testing.assert_allclose(mine, reference, atol=TOL)
