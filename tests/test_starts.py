"""Starting a solve from a solved posture (posturegen.solver.starts): the start is the solved
posture laid out for the new problem, it converges to the same posture in fewer iterations,
and NearestStarts returns the nearest verified solution of the same structure."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from posturegen import problem_from_dict, solve
from posturegen.solver.compile import numeric, symbolic
from posturegen.solver.problem import Program
from posturegen.solver.solve import configuration_from_x
from posturegen.solver.starts import NearestStarts, features, start_vector
from tests.test_solve import STAND


def _problem(target: list[float], yaw0: float = 0.0, **options: object):
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = target
    data.setdefault("options", {}).update(options)
    problem = problem_from_dict(data)
    if yaw0:  # another initial base rotation (the variables' R0)
        q = problem.q_init.copy()
        q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw0)).coeffs()
        problem.q_init = q
    return problem


@pytest.fixture(scope="module")
def solved():
    problem = _problem([0.3, -0.3, 0.9])
    result = solve(problem)
    assert result.success, result.message
    return problem, result


def test_start_vector_is_the_solved_posture_for_another_r0(solved):
    """Laid out for a problem whose initial base yaw differs, the start's configuration is
    still the solved q (base rotation re-expressed against the new R0), forces carried."""
    _, result = solved
    other = Program.of(_problem([0.3, -0.3, 0.9], yaw0=0.4))
    layout = symbolic(other)
    x_init = numeric(other, layout)[0]
    x = start_vector(other, x_init, layout.x_index, result)
    q = configuration_from_x(other, layout, x)
    np.testing.assert_allclose(q[:3], result.q[:3], atol=1e-12)
    np.testing.assert_allclose(q[7:], result.q[7:], atol=1e-12)
    assert abs(abs(float(np.dot(q[3:7], result.q[3:7]))) - 1.0) < 1e-12  # same rotation
    forces = [n for n in layout.x_index if n.startswith("contact") or "force" in n]
    assert forces, sorted(layout.x_index)
    for name in forces:
        np.testing.assert_array_equal(x[layout.x_index[name]], result.x[result.x_blocks[name]])


def test_start_at_own_solution_converges_faster_to_the_same_posture(solved):
    """With the multipliers (IPOPT's warm start) a solution is confirmed in a few
    iterations; from its variables alone the barrier still has to come down."""
    problem, result = solved
    again = solve(problem, start=result)
    assert again.success, again.message
    assert again.iterations <= 3 < result.iterations
    np.testing.assert_allclose(again.q, result.q, atol=1e-5)
    primal = dataclasses.replace(result, lam_x=np.zeros(0), lam_g={})
    from_q = solve(problem, start=primal)
    assert from_q.success, from_q.message
    assert again.iterations < from_q.iterations < result.iterations
    np.testing.assert_allclose(from_q.q, result.q, atol=1e-5)


def test_start_from_a_neighbour_reaches_the_cold_posture():
    near = solve(_problem([0.3, -0.3, 0.9]))
    problem = _problem([0.33, -0.28, 0.92])
    cold = solve(problem)
    warm = solve(problem, start=near)
    assert cold.success and warm.success, (cold.message, warm.message)
    np.testing.assert_allclose(warm.q, cold.q, atol=1e-4)


def test_nearest_starts_picks_the_nearest_verified_solution(solved):
    problem, result = solved
    starts = NearestStarts()
    assert starts.nearest(problem) is None
    far_problem = _problem([0.2, -0.5, 1.1])
    far = solve(far_problem)
    starts.add(far_problem, far)
    starts.add(problem, result)
    assert len(starts) == 2
    query = _problem([0.31, -0.29, 0.9])
    assert starts.nearest(query) is result
    assert np.linalg.norm(features(query) - features(problem)) < 0.02
    # a failed solve is not kept; another structure has no start
    failed = type(result).__new__(type(result))
    object.__setattr__(failed, "success", False)
    starts.add(query, failed)
    assert len(starts) == 2
    data = copy.deepcopy(STAND)
    data["tasks"] = []  # another structure: no reach task
    other = problem_from_dict(data)
    assert other.key() != problem.key()
    assert starts.nearest(other) is None


def test_a_start_with_multipliers_warm_starts_ipopt_from_its_own_barrier(solved, monkeypatch):
    """The first run from a solved posture's multipliers is IPOPT's warm start from
    START_WARM_MU_INIT (fewer iterations than the active-set rounds' 1e-5, measured); without
    multipliers the barrier starts at START_MU_INIT."""
    import posturegen.solver.solve as S
    from posturegen.solver.starts import START_MU_INIT, START_WARM_MU_INIT

    problem, result = solved
    seen: list[dict] = []
    run_nlp = S.run_nlp

    def recording(program, *args, **kwargs):
        runs = run_nlp(program, *args, **kwargs)
        seen.append(runs[-1].compiled.ipopt_options)
        return runs

    monkeypatch.setattr(S, "run_nlp", recording)
    warm = solve(_problem([0.31, -0.29, 0.9]), start=result)
    assert warm.success, warm.message
    assert seen[0]["ipopt.warm_start_init_point"] == "yes"
    assert seen[0]["ipopt.mu_init"] == START_WARM_MU_INIT != 1e-5
    seen.clear()
    primal = dataclasses.replace(result, lam_x=np.zeros(0), lam_g={})
    assert solve(_problem([0.31, -0.29, 0.9]), start=primal).success
    assert "ipopt.warm_start_init_point" not in seen[0]
    assert seen[0]["ipopt.mu_init"] == START_MU_INIT
