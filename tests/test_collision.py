"""Collision avoidance: proxies contain their meshes, smooth distances have the right
gradients, and postures that collide without the rows do not with them (coal on the meshes)."""

from __future__ import annotations

import copy
import sys

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen import problem_from_dict, solve
from posturegen.cli import _demo_dir
from posturegen.collision.boxes import BETA
from posturegen.collision.mesh_check import mesh_collision_checks
from posturegen.collision.proxies import proxy_model
from posturegen.collision.proxy_fit import EXCESS
from posturegen.collision.surface import refine, surface_of
from posturegen.errors import InputError
from posturegen.model.robot import load_robot
from posturegen.solver import compile as compile_module
from posturegen.solver.problem import Program
from tests.conftest import first_run_stops_early

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
ROBOTS = {
    "talos": "talos",
    "hrp2": "hrp2",
    "atlas": "atlas",
}


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_proxies_contain_every_mesh_surface_and_stand_out_at_most_the_excess(name):
    """Every point of every collision object's surface (meshes and primitives: the corners
    and centroids of its triangles refined to 5 mm edges, and random points on them) lies in
    a sphere of its joint, and no sphere stands more than EXCESS outside (its record)."""
    robot = load_robot(ROBOTS[name])
    pm = proxy_model(robot)
    by_joint: dict[int, list] = {}
    for s in pm.spheres:
        by_joint.setdefault(s.joint_id, []).append(s)
    rng = np.random.default_rng(0)
    for obj in robot.collision_model().geometryObjects:
        surface = surface_of(obj)
        V, F = refine(surface.vertices, surface.triangles, 0.005)
        w = rng.dirichlet(np.ones(3), len(F))
        points = np.vstack([V, V[F].mean(axis=1), np.einsum("tk,tki->ti", w, V[F])])
        spheres = by_joint[int(obj.parentJoint)]
        c = np.array([s.center for s in spheres])
        r = np.array([s.radius for s in spheres])
        for k in range(0, len(points), 4096):
            gap = np.linalg.norm(points[k : k + 4096, None] - c[None], axis=2) - r
            assert gap.min(axis=1).max() <= surface.sagitta + 1e-9, f"{name}: {obj.name}"
    assert max(s.excess for s in pm.spheres) <= EXCESS + 1e-9
    assert len(pm.joint_pairs) > 0


@given(
    half=st.tuples(*[st.floats(0.005, 0.15)] * 3),
    kind=st.sampled_from(["box", "cylinder", "capsule", "sphere"]),
)
@settings(max_examples=12, deadline=None)
def test_fitted_spheres_cover_a_primitive_and_stand_out_at_most_the_excess(half, kind):
    """fit_joint on a box, cylinder, capsule or sphere of random size: points drawn on its
    true surface are inside the spheres, and points drawn on the spheres are at most EXCESS
    (plus the sampling's own 1 mm) from the solid."""
    import coal

    from posturegen.collision.proxy_fit import fit_joint

    a, b, c = half
    shape = {
        "box": lambda: coal.Box(2 * a, 2 * b, 2 * c),
        "cylinder": lambda: coal.Cylinder(a, 2 * b),
        "capsule": lambda: coal.Capsule(a, 2 * b),
        "sphere": lambda: coal.Sphere(a),
    }[kind]()
    obj = pin.GeometryObject("probe", 1, pin.SE3.Identity(), shape)
    spheres = fit_joint(1, [surface_of(obj)])
    rng = np.random.default_rng(0)
    centres = np.array([s.center for s in spheres])
    radii = np.array([s.radius for s in spheres])
    on_surface = _surface_points(shape, rng, 400)
    assert np.all(
        np.min(np.linalg.norm(on_surface[:, None] - centres, axis=2) - radii, axis=1) <= 1e-9
    )
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    for s in spheres:
        outside = _signed_distance(shape, s.center + s.radius * u)
        assert outside.max() <= EXCESS + 1e-3


def _surface_points(shape, rng, n):
    """n points on the true surface of a coal box, cylinder, capsule or sphere (at the origin)."""
    import coal

    u = rng.normal(size=(n, 3))
    if isinstance(shape, coal.Sphere):
        return shape.radius * u / np.linalg.norm(u, axis=1)[:, None]
    if isinstance(shape, coal.Box):
        h = np.asarray(shape.halfSide)
        p = rng.uniform(-1, 1, size=(n, 3)) * h
        axis = rng.integers(0, 3, n)
        p[np.arange(n), axis] = np.sign(rng.normal(size=n)) * h[axis]
        return p
    r, h = shape.radius, shape.halfLength
    t = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(-h, h, n)
    side = np.c_[r * np.cos(t), r * np.sin(t), z]
    if isinstance(shape, coal.Capsule):
        cap = r * u / np.linalg.norm(u, axis=1)[:, None]
        cap[:, 2] += np.sign(cap[:, 2]) * h
        return np.vstack([side, cap])
    rho = r * np.sqrt(rng.uniform(0, 1, n))
    ends = np.c_[rho * np.cos(t), rho * np.sin(t), np.sign(rng.normal(size=n)) * h]
    return np.vstack([side, ends])


def _signed_distance(shape, points):
    """Distances [m] of points to a coal primitive at the origin (< 0 inside)."""
    import coal

    out = []
    for p in points:
        out.append(
            coal.distance(
                coal.Sphere(1e-9),
                coal.Transform3s(np.eye(3), p),
                shape,
                coal.Transform3s(),
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )
        )
    return np.array(out)


def test_proxies_are_cached_on_disk(tmp_path, monkeypatch):
    """A robot with no shipped proxies (a user's own): the first look-up fits and writes the
    cache file, the next one reads it back."""
    from posturegen.collision import proxies

    monkeypatch.setattr(proxies, "read_shipped", lambda key: None)

    robot = load_robot(ROBOTS["hrp2"])
    real = proxy_model(robot)
    calls = []

    def fit(model, geometry, rule):
        calls.append(rule)
        return list(real.spheres), dict(real.report)

    monkeypatch.setattr(proxies, "fit_robot", fit)
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    monkeypatch.setattr(robot, "_proxy_model", None)  # force a fresh look-up
    first = proxy_model(robot)
    files = list((tmp_path / "proxies").glob("*.json"))
    assert len(files) == 1 and len(calls) == 1
    robot._proxy_model = None
    second = proxy_model(robot)
    assert len(calls) == 1  # read back, not fitted again
    assert [s.radius for s in second.spheres] == pytest.approx([s.radius for s in first.spheres])
    assert [s.excess for s in second.spheres] == pytest.approx([s.excess for s in first.spheres])


def _solved_with_rows(problem):
    """The Result of solving ``problem`` and what its last IPOPT run solved (the problem with
    its last collision rows, a :class:`posturegen.solver.problem.Program`)."""
    solve_module = sys.modules["posturegen.solver.solve"]
    result, runs = solve_module._solve_continued(Program.of(problem), None, [])
    return result, runs[-1].program


def _fd(fun, x, h=1e-6):
    return np.array([(fun(x + h * e) - fun(x - h * e)) / (2 * h) for e in np.eye(len(x))]).T


def test_distance_gradients_match_finite_differences():
    """The rows as the solver sees them: sphere-sphere and sphere-box distances of q."""
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    data["obstacles"] = [{"name": "box", "box": [0.3, 0.3, 0.3], "position": [0.45, -0.12, 0.9]}]
    result, problem = _solved_with_rows(problem_from_dict(data))
    compiled = problem.compile()
    assert {"collision.self", "collision.env"} <= set(compiled.g_index)
    x0, p, _, _ = problem.numeric(compiled)
    xs = ca.MX.sym("x", x0.size)
    g = compiled.nlp(xs, p)[1]
    rows = np.r_[
        np.arange(compiled.n_g)[compiled.g_index["collision.self"]],
        np.arange(compiled.n_g)[compiled.g_index["collision.env"]],
    ]
    jac = ca.Function("j", [xs], [ca.jacobian(g[rows.tolist()], xs)])
    rng = np.random.default_rng(5)
    for _ in range(3):
        x = x0 + 0.05 * rng.normal(size=x0.size)
        J = np.array(jac(x))
        J_fd = _fd(lambda v: np.array(compiled.nlp(v, p)[1]).ravel()[rows], x)
        np.testing.assert_allclose(J, J_fd, atol=1e-6 * max(1.0, np.abs(J).max()))
    assert result.success, result.message


def test_hand_built_derivatives_match_casadi_and_finite_differences():
    """The program's Jacobian and Hessian of the Lagrangian, with the collision rows' own
    derivatives (posturegen.collision.soft_min.soft_min_rows), against CasADi's automatic ones
    to 1e-9 and
    against central differences, at seeded random x and multipliers."""
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    data["obstacles"] = [{"name": "box", "box": [0.3, 0.3, 0.3], "position": [0.45, -0.12, 0.9]}]
    _, problem = _solved_with_rows(problem_from_dict(data))
    compile_module._PROGRAMS.clear()
    prog = compile_module.symbolic(problem)
    assert prog._derivatives is None  # built on first use: a solver made from the expressions
    compiled = problem.compile()
    assert set(prog.derivative_functions) == {"jac_g", "hess_lag"} and prog.derivative_key
    jac_g, hess_lag = prog.derivative_functions["jac_g"], prog.derivative_functions["hess_lag"]
    x, p_sym, f, g = prog.x, prog.p, prog.f, prog.g
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", g.shape[0])
    auto = ca.Function(
        "auto",
        [x, p_sym, lam_f, lam_g],
        [ca.jacobian(g, x), ca.hessian(lam_f * f + ca.dot(lam_g, g), x)[0], ca.gradient(f, x)],
    )
    x0, p, _, _ = problem.numeric(compiled)
    rows = np.r_[
        np.arange(compiled.n_g)[compiled.g_index["collision.self"]],
        np.arange(compiled.n_g)[compiled.g_index["collision.env"]],
    ]
    rng = np.random.default_rng(11)
    for _ in range(3):
        xv = x0 + 0.05 * rng.normal(size=x0.size)
        lam = rng.normal(size=compiled.n_g)
        J_auto, H_auto, grad_f = (np.array(v) for v in auto(xv, p, 0.7, lam))
        J = np.array(jac_g(xv, p)[1])
        upper = np.array(hess_lag(xv, p, 0.7, lam))
        H = upper + np.triu(upper, 1).T
        assert np.all(np.tril(upper, -1) == 0)
        np.testing.assert_allclose(J, J_auto, atol=1e-9 * np.abs(J_auto).max())
        np.testing.assert_allclose(H, H_auto, atol=1e-9 * np.abs(H_auto).max())
        J_fd = _fd(lambda v: np.array(compiled.nlp(v, p)[1]).ravel()[rows], xv)
        np.testing.assert_allclose(J[rows], J_fd, atol=1e-6 * max(1.0, np.abs(J).max()))

        def lagrangian_gradient(v, lam=lam):
            gf = np.array(auto(v, p, 0.7, lam)[2]).ravel()
            return 0.7 * gf + np.array(jac_g(v, p)[1]).T @ lam

        H_fd = _fd(lagrangian_gradient, xv)
        np.testing.assert_allclose(H, H_fd, atol=1e-5 * max(1.0, np.abs(H).max()))


def test_smooth_box_distance_is_conservative():
    """LSE_β(s) - log(6)/β <= max_k s_k <= true distance, for points around a box."""
    rng = np.random.default_rng(2)
    half = np.array([0.2, 0.1, 0.3])
    for c in rng.normal(size=(200, 3)) * 0.6:
        s = np.r_[c - half, -c - half]
        lse = s.max() + np.log(np.exp(BETA * (s - s.max())).sum()) / BETA - np.log(6) / BETA
        true = np.linalg.norm(np.maximum(np.abs(c) - half, 0))
        assert lse <= s.max() + 1e-12
        if true > 0:
            assert s.max() <= true + 1e-12


@pytest.mark.parametrize("target", [[0.15, 0.0, 0.95], [0.15, 0.2, 0.6]])
def test_self_collision_is_avoided_on_the_meshes(talos, target):
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = target
    free = solve(problem_from_dict(data))
    assert free.success
    # without the rows the arm goes through the body: coal sees it
    probe = copy.deepcopy(free.posture)
    probe["collision"] = {"self": True, "unchecked": [], "boxes": []}
    hits, _ = mesh_collision_checks(probe, talos.model, talos.collision_model(), free.q)
    assert hits[0].value > 0, "this target should make the arm cross the body"
    data["options"]["self_collision"] = True
    safe = solve(problem_from_dict(data))
    assert safe.success, safe.message
    assert safe.posture["checks"]["collision: self (meshes)"]["value"] == 0


def test_box_obstacle_is_avoided(talos):
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.45, -0.3, 0.75]
    data["obstacles"] = [{"name": "box", "box": [0.2, 0.2, 0.2], "position": [0.45, -0.3, 0.95]}]
    free = copy.deepcopy(data)
    free["options"]["environment_collision"] = False
    r_free = solve(problem_from_dict(free))
    probe = copy.deepcopy(r_free.posture)
    probe["collision"] = {
        "self": False,
        "unchecked": [],
        "boxes": [
            {
                "name": "box",
                "placement": pin.SE3(np.eye(3), np.array([0.45, -0.3, 0.95])).homogeneous.tolist(),
                "size": [0.2, 0.2, 0.2],
                "allowed_joints": [],
            }
        ],
    }
    checks, _ = mesh_collision_checks(probe, talos.model, talos.collision_model(), r_free.q)
    assert checks[0].value > 0
    r = solve(problem_from_dict(data))
    assert r.success, r.message
    assert r.posture["checks"]["collision: scene (meshes)"]["value"] == 0


def test_collision_options_are_validated():
    data = copy.deepcopy(STAND)
    data["options"]["collision_exclude"] = [["arm_right_4_link", "no_such_link"]]
    data["options"]["self_collision"] = True
    with pytest.raises(InputError, match="no_such_link"):
        problem_from_dict(data)
    data["options"]["collision_exclude"] = "all"
    with pytest.raises(InputError, match="collision_exclude"):
        problem_from_dict(data)
    data["options"]["collision_exclude"] = []
    data["options"]["collision_margin"] = -0.1
    with pytest.raises(InputError, match="collision_margin"):
        problem_from_dict(data)


def test_verify_file_runs_the_mesh_checks(tmp_path):
    from posturegen.verify import verify_file

    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    r = solve(problem_from_dict(data))
    assert r.success, r.message
    path = r.write(tmp_path / "posture.json")
    report = verify_file(path)
    names = {c.name for c in report.checks}
    assert {"collision: self (meshes)", "collision: scene (meshes)"} <= names
    assert report.ok


def test_a_failed_active_set_loop_restarts_from_the_collision_free_solution(monkeypatch):
    """solve(): when the loop fails, the program without collision rows is solved and the
    loop starts again from its solution; the Result counts every IPOPT run."""
    import sys

    solve_module = sys.modules["posturegen.solver.solve"]
    calls: list[tuple] = []
    step = first_run_stops_early(
        solve_module._solve_avoiding, calls, lambda _, x0, prior: (x0, len(prior))
    )
    monkeypatch.setattr(solve_module, "_solve_avoiding", step)
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.15, 0.0, 0.95]  # crosses the body without the rows
    data["options"]["self_collision"] = True
    result = solve(problem_from_dict(data))
    assert len(calls) == 2
    assert calls[0][0] is None and calls[1][0] is not None  # restarted from the relaxed x
    assert calls[1][1] >= 2  # the failed loop's runs and the relaxed run are counted
    assert result.success, result.message
    assert result.posture["ipopt_runs"] >= 3
    assert result.posture["checks"]["collision: self (meshes)"]["value"] == 0


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_the_reference_posture_passes_the_mesh_check_and_sets_the_clearances(name):
    """The reference posture is verified on the meshes (the pairs that overlap there are
    the rule's), and each candidate pair's clearance is its proxies' distance there."""
    robot = load_robot(ROBOTS[name])
    pm = proxy_model(robot)
    q = pm.rule.reference_q
    srdf = {"srdf": str(robot.srdf)} if robot.srdf else {}
    probe = {"robot": srdf, "collision": {"self": True, "unchecked": []}}
    checks, _ = mesh_collision_checks(probe, robot.model, robot.collision_model(), q)
    assert checks[0].value == 0, checks[0].detail
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    centers = pm.centers_world(robot.model, data)
    i, j, link = _all_pairs(pm)
    closest = np.full(len(pm.joint_pairs), np.inf)
    np.minimum.at(closest, link, pm.distances(centers, i, j))
    np.testing.assert_allclose(closest, pm.clearance, atol=1e-9)


def test_box_rows_are_conservative_exact_near_and_saturated_far(talos):
    """The solver's sphere-box rows r = -LSE(-d_β, -(m + s)) - m (d_β the smooth face distance
    minus the radius, s = ENV_SATURATION): r >= 0 implies the sphere is at least the margin
    from the box, r is within the LSE bound of d - m near the box, and r is the constant s
    (zero gradient) once the sphere is far."""
    from posturegen.collision.boxes import box_distances, row_box_distances
    from posturegen.collision.soft_min import ENV_SATURATION

    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.45, -0.3, 0.75]
    data["obstacles"] = [{"name": "box", "box": [0.2, 0.2, 0.2], "position": [0.45, -0.3, 0.95]}]
    result, problem = _solved_with_rows(problem_from_dict(data))
    assert result.success, result.message
    term = problem.collision_term
    compiled = problem.compile()
    live = [k for k, pair in enumerate(term.env_rows()) if pair is not None]  # free slots out
    rows = np.arange(compiled.n_g)[compiled.g_index["collision.env"]][live]
    x0, p, lbg, ubg = problem.numeric(compiled)
    xs = ca.SX.sym("x", x0.size)
    g = compiled.nlp(xs, p)[1][rows.tolist()]
    fn = ca.Function("rows", [xs], [g, ca.jacobian(g, xs)])
    bounds = {"lbx": compiled.lbx, "ubx": compiled.ubx, "lbg": lbg, "ubg": ubg}
    margin = term.margin
    sphere = np.array([term.env_rows()[k][0] for k in live])
    box = np.array([term.env_rows()[k][1] for k in live])
    rng = np.random.default_rng(11)
    near = far = 0
    for x in [x0, compiled.solver(x0=x0, p=p, **bounds)["x"]] + [
        x0 + 0.3 * rng.normal(size=x0.size) for _ in range(6)
    ]:
        x = np.array(x).ravel()
        r, J = (np.array(v) for v in fn(x))
        r = r.ravel()
        q = _configuration(problem, compiled, x)
        pdata = talos.model.createData()
        pin.forwardKinematics(talos.model, pdata, q)
        d = box_distances(term.pm, term.pm.centers_world(talos.model, pdata), term.boxes)
        d = d[sphere, box]  # max-face distance minus radius: a lower bound of the true one
        assert np.all(r <= d - margin + 1e-9)
        # the active set's distances are the rows' own (up to the saturation, 1.2e-5 m at 2 cm)
        d_row = row_box_distances(term.pm, term.pm.centers_world(talos.model, pdata), term.boxes)
        d_row = d_row[sphere, box]
        assert np.all(r <= d_row - margin + 1e-9)
        np.testing.assert_allclose(
            r[d_row - margin < 0.02], (d_row - margin)[d_row - margin < 0.02], atol=2e-5
        )
        close = d - margin < 0.02
        # LSE of the faces: at most log(6)/β low; the saturation term adds e^(-β_min s) at most
        np.testing.assert_array_less(d[close] - margin - r[close], np.log(6.0) / BETA + 1e-6)
        apart = d - margin > ENV_SATURATION + 0.05
        np.testing.assert_allclose(r[apart], ENV_SATURATION, atol=1e-4)
        assert np.abs(J[apart]).max(initial=0.0) < 1e-3
        near, far = near + close.sum(), far + apart.sum()
    assert near > 0 and far > 0  # both regimes were seen


def _configuration(problem, compiled, x):
    from posturegen.solver.solve import configuration_from_x

    return configuration_from_x(problem, compiled, np.asarray(x).ravel())


def _random_postures(robot, seed: int, n: int):
    """n postures with joints drawn uniformly within their limits, ``data`` filled by them."""
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(seed)
    for _ in range(n):
        q = robot.q_init.copy()
        q[7:] = rng.uniform(robot.q_lower, robot.q_upper)
        pin.forwardKinematics(model, data, q)
        yield model, data


def test_vectorized_proxy_centres_match_pinocchio(talos):
    pm = proxy_model(talos)
    for model, data in _random_postures(talos, 3, 3):
        expected = np.array([data.oMi[s.joint_id].act(s.center) for s in pm.spheres])
        np.testing.assert_allclose(pm.centers_world(model, data), expected, atol=1e-12)


def test_mesh_box_check_finds_what_a_brute_force_check_finds(talos):
    """The broad phase (bounding spheres of the collision objects) never hides a hit: boxes
    dropped at random around the robot fail the check exactly when coal on every object
    finds one more than TOL_PENETRATION inside."""
    import coal

    from posturegen.collision.mesh_check import TOL_PENETRATION

    model, geometry, q = talos.model, talos.collision_model(), talos.q_init
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    gdata = geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, gdata)
    rng = np.random.default_rng(7)
    seen = 0
    for _ in range(25):
        size = rng.uniform(0.05, 0.4, 3)
        T = pin.SE3(
            pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)),
            q[:3] + rng.normal(size=3) * [0.3, 0.3, 0.5],
        )
        box = {"name": "b", "placement": T.homogeneous.tolist(), "size": size.tolist()}
        probe = {"robot": {}, "collision": {"self": False, "boxes": [box]}}
        value = mesh_collision_checks(probe, model, geometry, q)[0][0].value
        shape = coal.Box(*(size - 2 * TOL_PENETRATION))
        brute = 0
        for k, obj in enumerate(geometry.geometryObjects):
            M = gdata.oMg[k]
            res = coal.CollisionResult()
            brute += coal.collide(
                obj.geometry,
                coal.Transform3s(M.rotation, M.translation),
                shape,
                coal.Transform3s(T.rotation, T.translation),
                coal.CollisionRequest(),
                res,
            )
        assert (value > TOL_PENETRATION) == (brute > 0)  # the deepest hit, or 0 for none
        seen += brute > 0
    assert 0 < seen < 25  # boxes both touching and missing the robot were drawn


def _all_pairs(pm):
    """Every candidate sphere pair (i, j) and its joint pair index, listed (brute force)."""
    i, j, link = [], [], []
    for k, (a, b) in enumerate(pm.joint_pairs):
        A, B = np.flatnonzero(pm.joint_ids == a), np.flatnonzero(pm.joint_ids == b)
        i.append(np.repeat(A, len(B)))
        j.append(np.tile(B, len(A)))
        link.append(np.full(len(A) * len(B), k))
    return np.concatenate(i), np.concatenate(j), np.concatenate(link)


def _drawn_slacks(robot, pm, seed: int, withins: tuple[float, ...]):
    """(centres (S, 3), every candidate pair's distance, a slack (P,) [m]) at 11 random
    postures, for each base slack in ``withins`` plus up to 2 cm drawn per joint pair."""
    i, j, _ = _all_pairs(pm)
    rng = np.random.default_rng(seed)
    for model, data in _random_postures(robot, seed, 11):
        centers = pm.centers_world(model, data)
        exact = pm.distances(centers, i, j)
        for within in withins:
            slack = np.full(len(pm.joint_pairs), within) + rng.uniform(0, 0.02, len(pm.joint_pairs))
            yield centers, exact, slack


def test_broad_phase_of_the_self_pairs_keeps_every_close_pair(talos):
    """close_pairs: exact distances, and exactly the candidate pairs closer than their joint
    pair's slack (random postures, several slacks), against every pair computed; with joint
    pairs restricted, none of the others."""
    pm = proxy_model(talos)
    i, j, link = _all_pairs(pm)
    for centers, exact, slack in _drawn_slacks(talos, pm, 1, (0.0, 0.06, 0.3)):
        close = pm.close_pairs(centers, slack)
        expected = np.flatnonzero(exact < slack[link])
        assert len(close.d) == len(expected)
        got = set(zip(close.i.tolist(), close.j.tolist(), strict=True))
        assert got == set(zip(i[expected].tolist(), j[expected].tolist(), strict=True))
        np.testing.assert_allclose(np.sort(close.d), np.sort(exact[expected]), atol=1e-12)
    links = np.arange(0, len(pm.joint_pairs), 3)
    close = pm.close_pairs(centers, np.full(len(pm.joint_pairs), 0.3), links)
    assert len(close.d) and np.isin(close.link, links).all()


@pytest.mark.parametrize("per_link", [1, 16])
def test_the_closest_pairs_of_each_joint_pair_are_found_without_measuring_all(talos, per_link):
    """closest_pairs: the per_link closest candidate pairs of each joint pair within its
    slack, against every pair computed and sorted (random postures, a tight and a wide
    slack); with joint pairs restricted, none of the others."""
    pm = proxy_model(talos)
    i, j, link = _all_pairs(pm)
    for centers, exact, slack in _drawn_slacks(talos, pm, 7, (0.01, 0.06, 0.3)):
        got = pm.closest_pairs(centers, slack, per_link)
        inside = np.flatnonzero(exact < slack[link])
        order = inside[np.lexsort((exact[inside], link[inside]))]
        rank = np.arange(len(order)) - np.searchsorted(link[order], link[order])
        want = order[rank < per_link]
        assert len(got.d) == len(want)
        pairs = zip(i[want].tolist(), j[want].tolist(), strict=True)
        assert got.tuples() == {(min(a, b), max(a, b)) for a, b in pairs}
        np.testing.assert_allclose(np.sort(got.d), np.sort(exact[want]), atol=1e-12)
    links = np.arange(0, len(pm.joint_pairs), 3)
    got = pm.closest_pairs(centers, np.full(len(pm.joint_pairs), 0.3), per_link, links)
    assert len(got.d) and np.isin(got.link, links).all()


def test_the_separated_start_parts_pressed_pairs_and_keeps_the_supports(talos):
    """Talos' upper arms pressed against its torso (shoulder roll 0.05 rad): the first start
    moves the joints that carry no contact so that the pairs closer than margin + SEPARATION
    get apart (the sum of their shortfalls shrinks by a fifth), leaves the pairs that the
    reference posture already holds closer than the margin no closer, and the legs (they
    carry the feet) alone."""
    from posturegen.collision.separation import SEPARATION, separated_start

    pm = proxy_model(talos)
    model = talos.model
    feet = [talos.patches[n].joint_id for n in ("left_sole", "right_sole")]
    margin = 0.002
    q0 = talos.q_init.copy()
    for name, value in (("arm_left_2_joint", 0.05), ("arm_right_2_joint", -0.05)):
        q0[model.joints[model.getJointId(name)].idx_q] = value
    qj = separated_start(talos, pm, np.arange(len(pm.joint_pairs)), margin, q0, feet)
    held = pm.pair_clearance(margin)
    i, j, link = _all_pairs(pm)

    def closest(q):
        """(P,) each joint pair's closest proxies [m]."""
        data = model.createData()
        pin.forwardKinematics(model, data, q)
        d = pm.distances(pm.centers_world(model, data), i, j)
        out = np.full(len(pm.joint_pairs), np.inf)
        np.minimum.at(out, link, d)
        return out

    q = q0.copy()
    q[7:] = qj
    before, after = closest(q0), closest(q)
    legs = [k for k, n in enumerate(talos.joint_names) if n.startswith("leg_")]
    np.testing.assert_array_equal(qj[legs], q0[7:][legs])
    assert np.all((talos.q_lower <= qj) & (qj <= talos.q_upper))
    names = [(model.names[int(a)], model.names[int(b)]) for a, b in pm.joint_pairs]
    arms = np.array(["arm" in a or "arm" in b for a, b in names]) & (pm.clearance >= margin)
    short_before = np.maximum(margin + SEPARATION - before, 0)[arms]
    short_after = np.maximum(margin + SEPARATION - after, 0)[arms]
    assert short_before.max() > 0.5 * SEPARATION  # pressed at the start
    assert short_after.sum() < 0.8 * short_before.sum()  # parted (Talos: 20.2 -> 14.3 cm)
    tight = pm.clearance < margin  # held at their reference clearance: no closer than that
    assert np.all(after[tight] >= np.minimum(before[tight], held[tight]) - 1e-6)
    legs_only = np.array(["leg" in a and "leg" in b for a, b in names])
    np.testing.assert_allclose(after[legs_only], before[legs_only], atol=1e-9)


def test_collision_runs_start_ipopt_with_their_barrier_and_regularization(monkeypatch):
    """The active-set runs use COLLISION_MU_INIT and COLLISION_PERTURBATION (IPOPT's options
    carry them), the problem's own options are never written."""
    import sys

    solve_module = sys.modules["posturegen.solver.solve"]
    seen = []
    run = solve_module.run_nlp

    def spy(problem, *args, **kwargs):
        seen.append(problem.solver_options.ipopt())
        return run(problem, *args, **kwargs)

    monkeypatch.setattr(solve_module, "run_nlp", spy)
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    problem = problem_from_dict(data)
    before = problem.solver_options
    assert "ipopt.first_hessian_perturbation" not in before.ipopt()
    result = solve(problem)
    assert result.success, result.message
    first, factor = solve_module.COLLISION_PERTURBATION
    assert seen[0]["ipopt.mu_init"] == solve_module.COLLISION_MU_INIT
    assert seen[0]["ipopt.first_hessian_perturbation"] == first
    assert seen[0]["ipopt.perturb_inc_fact_first"] == factor
    assert problem.solver_options == before


@pytest.mark.parametrize("method", ["sqp", "ipopt"])
def test_only_ipopts_collision_runs_start_from_the_separated_start(monkeypatch, method):
    """IPOPT's first collision run starts from q_init with its pressed pairs parted (Talos'
    forearms by its thighs at half-sitting); the SQP's from q_init's joints themselves (the
    separated start bought it no posture and cost 3.4 ms a new stance)."""
    import sys

    solve_module = sys.modules["posturegen.solver.solve"]
    starts = []
    run = solve_module.run_nlp

    def spy(problem, *args, **kwargs):
        starts.append(kwargs.get("joints0"))
        return run(problem, *args, **kwargs)

    monkeypatch.setattr(solve_module, "run_nlp", spy)
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    data["options"]["solver"] = {"method": method}
    problem = problem_from_dict(data)
    result = solve(problem)
    assert result.success, result.message
    if method == "sqp":
        assert starts[0] is None
    else:
        assert starts[0] is not None
        assert np.abs(starts[0] - problem.q_init[7:]).max() > 1e-3  # the forearms moved


def test_row_box_distances_below_a_threshold_are_exact_and_the_others_read_inf(talos):
    """row_box_distances(..., below): the pairs nearer than ``below`` [m] read the rows' LSE
    distance over the six faces (computed here face by face), the others +inf, and only
    those whose distance is at least ``below``."""
    from posturegen.collision.boxes import BETA, EnvBox, row_box_distances
    from posturegen.collision.proxies import proxy_model

    pm = proxy_model(talos)
    model, pdata = talos.model, talos.model.createData()
    pin.seed(5)  # pinocchio's randomConfiguration draws from its own generator
    boxes = [
        EnvBox(
            "a",
            pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 1.0), np.array([0.3, -0.2, 0.8])),
            np.array([0.2, 0.1, 0.3]),
            frozenset(),
        ),
        EnvBox(
            "b",
            pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.05])),
            np.array([2.0, 2.0, 0.05]),
            frozenset(),
        ),
    ]
    inf_count = finite_count = 0
    for _ in range(4):
        q = pin.randomConfiguration(
            model,
            np.maximum(model.lowerPositionLimit, -0.5),
            np.minimum(model.upperPositionLimit, 0.5),
        )
        pin.forwardKinematics(model, pdata, q)
        centers = pm.centers_world(model, pdata)  # (S, 3)
        exact = np.empty((len(centers), len(boxes)))
        for k, b in enumerate(boxes):
            local = (centers - b.T_world_box.translation) @ b.T_world_box.rotation
            faces = np.concatenate([local - b.half, -local - b.half], axis=1)  # (S, 6)
            top = faces.max(axis=1)
            lse = top + np.log(np.exp(BETA * (faces - top[:, None])).sum(axis=1)) / BETA
            exact[:, k] = lse - np.log(6.0) / BETA - pm.radii
        # bit for bit: the rows' holds follow these values
        np.testing.assert_array_equal(row_box_distances(pm, centers, boxes), exact)
        for below in (0.0, 0.05, 0.3):
            d = row_box_distances(pm, centers, boxes, below)
            far = np.isinf(d)
            assert np.all(exact[far] >= below)
            np.testing.assert_array_equal(d[~far], exact[~far])
            assert np.all(~far[exact < below])
            inf_count, finite_count = inf_count + far.sum(), finite_count + (~far).sum()
    assert inf_count > 0 and finite_count > 0  # both kinds met
