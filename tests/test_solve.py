"""Solving, the frozen result, solver reuse, the posture file and the independent re-check."""

from __future__ import annotations

import concurrent.futures
import copy
import dataclasses
import json

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import posturegen
from posturegen import load_problem, problem_from_dict, solve
from posturegen.cli import _demo_dir, main
from posturegen.verify import verify_posture
from tests.conftest import HRP2_URDF, first_run_stops_early

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


@pytest.fixture(scope="module")
def result():
    return solve(load_problem(_demo_dir() / "stand-reach.yaml"))


def test_demo_posture_is_verified(result, talos):
    assert result.success, result.message
    assert result.status == "Solve_Succeeded"
    assert result.verification.ok
    assert result.q.shape == (talos.model.nq,)
    assert abs(np.linalg.norm(result.q[3:7]) - 1) < 1e-12
    # both feet carry the whole weight, upward
    total = sum(f.force for fs in result.forces.values() for f in fs)
    np.testing.assert_allclose(total, [0, 0, talos.weight], atol=1e-6 * talos.weight)
    assert np.all(np.abs(result.torques) <= talos.effort_limit + 1e-9)


def test_result_is_frozen(result):
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.success = False  # type: ignore[misc]


def test_solver_is_built_once_per_structure():
    a = load_problem(_demo_dir() / "stand-reach.yaml")
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.35, -0.45, 1.0]
    data["contacts"][0]["position"] = [0.05, 0.12]
    b = problem_from_dict(data)
    assert a.compile() is b.compile()
    rb = solve(b)
    assert rb.success, rb.message
    assert rb.build_time_s == 0.0
    # the new target and foot pose were honoured, not the cached ones
    assert rb.posture["tasks"][0]["target"] == [0.35, -0.45, 1.0]
    assert rb.posture["contacts"][0]["pose"]["position"] == [0.05, 0.12]


def test_posture_file_schema(result):
    p = result.posture
    for key in (
        "schema",
        "robot",
        "q",
        "torques",
        "gravity",
        "success",
        "status",
        "iterations",
        "solve_time_s",
        "max_violation",
        "contacts",
        "obstacles",
        "self_collision",
    ):
        assert key in p
    assert p["schema"] == "posturegen.posture/1"
    c = p["contacts"][0]
    assert set(c) >= {"name", "type", "mu", "robot_patch", "surface", "ellipse", "forces"}
    assert np.array(c["robot_patch"]["placement"]).shape == (4, 4)
    assert np.array(c["surface"]["placement"]).shape == (4, 4)
    assert len(c["forces"]) == 4 and set(c["forces"][0]) == {"frame", "point", "force"}
    json.dumps(p)  # serializable


def _tampered(posture, edit):
    p = copy.deepcopy(posture)
    edit(p)
    return p


@pytest.mark.parametrize(
    ("edit", "check"),
    [
        (lambda p: p["torques"].__setitem__(3, p["torques"][3] + 5.0), "static equilibrium"),
        (lambda p: p["q"].__setitem__(10, p["q"][10] + 0.01), "contact geometry"),
        (lambda p: p["q"].__setitem__(12, 10.0), "joint limits"),
        (lambda p: p["contacts"][0]["forces"][0]["force"].__setitem__(0, 1e3), "friction cones"),
        (
            lambda p: p["contacts"][0]["forces"][0]["point"].__setitem__(0, 0.5),
            "contact points inside polygons",
        ),
        (lambda p: p["tasks"][0].__setitem__("target", [0.5, -0.35, 0.9]), "tasks"),
        (lambda p: p["torques"].__setitem__(0, 1e4), "torque limits"),
    ],
    ids=["torque", "foot-moved", "joint-limit", "friction", "point-outside", "task", "effort"],
)
def test_verify_rejects_tampered_postures(result, talos, edit, check):
    report = verify_posture(_tampered(result.posture, edit), talos.model)
    assert not report.ok
    assert check in {c.name for c in report.failures}


def test_cli_demo_then_verify(tmp_path, capsys):
    assert main(["demo", "stand-reach", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "problem.yaml").is_file()
    assert main(["verify", str(tmp_path / "posture.json")]) == 0
    out = capsys.readouterr().out
    assert "posture verified" in out
    # a tampered file is rejected with exit code 1
    data = json.loads((tmp_path / "posture.json").read_text())
    data["torques"][5] += 3.0
    (tmp_path / "bad.json").write_text(json.dumps(data))
    assert main(["verify", str(tmp_path / "bad.json")]) == 1
    assert "REJECTED" in capsys.readouterr().out


def test_unreachable_target_is_exit_1_with_a_file(tmp_path, capsys):
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.4, -0.3, 2.5]
    path = tmp_path / "far.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["solve", str(path), "--out", str(tmp_path / "out")]) == 1
    posture = json.loads((tmp_path / "out" / "posture.json").read_text())
    assert posture["success"] is False
    assert posture["message"]


def test_iteration_limit_is_never_a_success():
    data = copy.deepcopy(STAND)
    data["options"]["solver"] = {"max_iter": 2}
    r = solve(problem_from_dict(data))
    assert not r.success
    assert r.status == "Maximum_Iterations_Exceeded"


def test_torque_limits_bind(talos):
    """With the limits scaled down to 40 %, the posture that was fine at 100 % must change:
    every torque stays within the scaled limit and at least one sits on it."""
    data = copy.deepcopy(STAND)
    data["tasks"][0]["target"] = [0.8, -0.2, 0.5]
    free = solve(problem_from_dict(data))
    assert free.success, free.message
    ratio = np.abs(free.torques) / talos.effort_limit
    assert ratio.max() > 0.5
    data["options"]["torque_limit_scale"] = 0.5
    tight = solve(problem_from_dict(data))
    assert tight.success, tight.message
    ratio = np.abs(tight.torques) / talos.effort_limit
    assert ratio.max() <= 0.5 * (1 + 1e-6)
    assert ratio.max() >= 0.5 * (1 - 1e-4)
    # the re-check uses the scaled limits too
    bad = copy.deepcopy(tight.posture)
    bad["torque_limit_scale"] = 0.3
    assert "torque limits" in {c.name for c in verify_posture(bad, talos.model).failures}


def test_custom_urdf_with_patch_file(tmp_path):
    """HRP-2 loaded by path (the URDF posturegen ships) with the patch file named, standing and
    reaching."""
    data = copy.deepcopy(STAND)
    data["robot"] = {
        "urdf": str(HRP2_URDF),
        "srdf": str(HRP2_URDF.with_suffix(".srdf")),
        "patches": "hrp2",
    }
    data["tasks"] = [{"type": "position", "frame": "r_gripper", "target": [0.35, -0.25, 0.75]}]
    r = solve(problem_from_dict(data))
    assert r.success, r.message
    assert r.posture["robot"]["urdf"] == str(HRP2_URDF.resolve())


def test_cli_inspect_lists_the_program(capsys):
    assert main(["inspect", str(_demo_dir() / "stand-reach.yaml")]) == 0
    out = capsys.readouterr().out
    assert "variables: 62" in out
    assert "contact.left_sole.friction: 16" in out
    assert "torque_limits: 32" in out


@settings(max_examples=200, deadline=None)
@given(
    lo=st.floats(-3, 3),
    width=st.floats(0, 6),
    t=st.floats(-0.5, 1.5),
)
def test_posture_reference_is_put_inside_the_limits(lo, width, t):
    """A reference on or past a limit moves min(REFERENCE_INSET, range/4) inside it; one
    already that far inside is kept."""
    from posturegen.terms.costs import REFERENCE_INSET, reference_inside_limits

    hi = lo + width
    q0 = np.array([lo + t * width])
    out = reference_inside_limits(q0, np.array([lo]), np.array([hi]))[0]
    inset = min(REFERENCE_INSET, width / 4)
    assert lo + inset - 1e-12 <= out <= hi - inset + 1e-12
    if lo + inset <= q0[0] <= hi - inset:
        assert out == q0[0]


def test_a_reference_on_a_limit_no_longer_slows_ipopt_down(monkeypatch):
    """Talos' grippers sit on their upper limit in half-sitting: with the posture reference
    there, the optimum is a degenerate active bound and IPOPT's steps halve each iteration; a
    reference 1 cm inside converges quadratically (12 instead of 16 iterations here). (The
    SQP, an active-set method, takes 5 either way.)"""
    import posturegen.terms.costs as costs

    runs = {}
    data = copy.deepcopy(STAND)
    data["options"]["solver"] = {"method": "ipopt"}
    for inset in (0.0, costs.REFERENCE_INSET):
        monkeypatch.setattr(costs, "REFERENCE_INSET", inset)
        runs[inset] = solve(problem_from_dict(copy.deepcopy(data)))
        assert runs[inset].success, runs[inset].message
    plain, inset = runs[0.0], runs[costs.REFERENCE_INSET]
    assert inset.iterations <= plain.iterations - 3
    names = inset.posture["joint_names"]
    gripper = 7 + names.index("gripper_right_joint")
    assert inset.q[gripper] == pytest.approx(-costs.REFERENCE_INSET, abs=1e-4)


def test_a_run_that_does_not_converge_restarts_from_the_torque_relaxed_solution(monkeypatch):
    """solve(): when IPOPT does not converge, the problem is solved with its torque limits
    ×TORQUE_CONTINUATION, and the real one again from that solution; every run counts."""
    import sys

    solve_module = sys.modules["posturegen.solver.solve"]
    calls: list[tuple[float, bool]] = []
    step = first_run_stops_early(
        solve_module._solve_continued,
        calls,
        lambda p, x0, _: (p.torque_limit_scale, x0 is not None),
    )
    monkeypatch.setattr(solve_module, "_solve_continued", step)
    data = copy.deepcopy(STAND)
    data["options"]["solver"] = {"method": "ipopt"}  # one run per step (auto: SQP, IPOPT)
    problem = problem_from_dict(data)
    result = solve(problem)
    scale = solve_module.TORQUE_CONTINUATION
    assert calls == [(1.0, False), (scale, False), (1.0, True)]
    assert problem.torque_limit_scale == 1.0  # never written
    assert result.success, result.message
    assert result.posture["torque_limit_scale"] == 1.0
    assert result.posture["ipopt_runs"] == 3
    assert result.iterations > 3


@pytest.mark.parametrize("preset", [None, "2"])
def test_importing_posturegen_makes_blas_single_threaded_unless_set(preset):
    """posturegen._threads: OPENBLAS_NUM_THREADS defaults to 1; a user's value stays."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if preset is not None:
        env["OPENBLAS_NUM_THREADS"] = preset
    code = "import posturegen, os; print(os.environ['OPENBLAS_NUM_THREADS'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == (preset or "1")


def _collision_stand() -> dict:
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    data["obstacles"] = [{"name": "box", "box": [0.3, 0.3, 0.3], "position": [0.45, -0.12, 0.9]}]
    return data


def test_solve_never_writes_on_the_problem():
    """solve() is a pure function of the problem: what it shows and keys on is the same after
    a solve (collision rows, continuations and solver options are the solve's own), and the
    same problem solved again, from the same caches' state, gives the same posture."""
    problem = problem_from_dict(_collision_stand())
    before = (
        problem.summary(),
        problem.key(),
        problem.torque_limit_scale,
        problem.solver_options,
        problem.collision_options,
    )
    posturegen.clear_caches()
    first = solve(problem)
    after = (
        problem.summary(),
        problem.key(),
        problem.torque_limit_scale,
        problem.solver_options,
        problem.collision_options,
    )
    assert after == before
    assert "collision" not in problem.summary()
    # the collision rows were the solve's own: its last program had them, the problem has not
    assert first.constraint_rows > sum(problem.constraint_counts().values())
    posturegen.clear_caches()
    second = solve(problem)
    assert first.success, first.message
    np.testing.assert_array_equal(first.q, second.q)
    assert first.iterations == second.iterations


def test_one_problem_solved_from_two_threads_gives_the_serial_results():
    """Two threads solving the same Problem at once get what one thread gets."""
    problem = problem_from_dict(copy.deepcopy(STAND))
    serial = solve(problem)
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda _: solve(problem), range(4)))
    for r in results:
        assert r.success, r.message
        np.testing.assert_array_equal(r.q, serial.q)
        assert r.iterations == serial.iterations


def test_a_call_budget_starts_no_run_once_spent(monkeypatch, result):
    """options.solver.max_call_iter bounds a whole call: runs that stop at max_iter are
    followed by continuations (collision-free, torque-relaxed), but not once the call's
    iterations are spent; the failure says why. A budget not reached changes nothing, and it
    is not part of the structure (the demo's compiled program serves it)."""
    import sys

    solve_module = sys.modules["posturegen.solver.solve"]
    runs: list[int] = []
    run_nlp = solve_module.run_nlp

    def counted(*args, **kwargs):
        runs.append(1)
        return run_nlp(*args, **kwargs)

    monkeypatch.setattr(solve_module, "run_nlp", counted)
    data = copy.deepcopy(STAND)
    data["options"]["self_collision"] = True
    data["options"]["solver"] = {"max_iter": 3, "method": "ipopt"}
    unbounded = solve(problem_from_dict(data))
    assert not unbounded.success and len(runs) > 1
    runs.clear()
    data["options"]["solver"]["max_call_iter"] = 3
    bounded = solve(problem_from_dict(data))
    assert not bounded.success and len(runs) == 1 and bounded.iterations == 3
    assert "max_call_iter" in bounded.message
    runs.clear()
    data["options"]["solver"]["method"] = "auto"  # the SQP's call, then IPOPT's: each its own
    both = solve(problem_from_dict(data))
    assert not both.success and len(runs) == 2 and "max_call_iter" in both.message
    assert both.iterations_by_method == {"sqp": 3, "ipopt": 3} and both.iterations == 6
    data = copy.deepcopy(STAND)
    data["options"]["solver"] = {"max_call_iter": 1000}
    roomy = solve(problem_from_dict(data))
    assert roomy.success and roomy.build_time_s == 0.0
    assert roomy.iterations == result.iterations
    np.testing.assert_array_equal(roomy.q, result.q)


def test_a_run_uses_only_what_is_left_of_the_call_budget():
    """A run starts with the budget's remainder as its max_iter (rounded up to BUDGET_STEP):
    the stances family's problem 28 (narrow yawed stance, the knees pressed together) spends
    hundreds of iterations unbounded; with a budget of 40 the call stops within 40 +
    BUDGET_STEP - 1, where a run allowed its whole max_iter (200) would not."""
    import dataclasses

    from posturegen.bench.reach import stances_family
    from posturegen.solver.runs import BUDGET_STEP

    problem = list(stances_family(29, 0))[28]
    problem.solver_options = dataclasses.replace(
        problem.solver_options, max_call_iter=40, codegen="off", method="ipopt"
    )
    assert problem.solver_options.max_iter > 40 + BUDGET_STEP
    result = solve(problem)
    assert not result.success and "max_call_iter" in result.message
    assert 40 <= result.iterations <= 40 + BUDGET_STEP - 1
    # under auto, the SQP's call and IPOPT's each within it
    problem.solver_options = dataclasses.replace(problem.solver_options, method="auto")
    both = solve(problem)
    assert not both.success and set(both.iterations_by_method) == {"sqp", "ipopt"}
    assert all(40 <= n <= 40 + BUDGET_STEP - 1 for n in both.iterations_by_method.values())


@pytest.mark.parametrize("value", [0, -1, 2.5, True, "10"])
def test_a_bad_call_budget_is_a_one_line_error(value):
    data = copy.deepcopy(STAND)
    data["options"]["solver"] = {"max_call_iter": value}
    with pytest.raises(posturegen.InputError, match="options.solver.max_call_iter"):
        problem_from_dict(data)
