"""The never-seen pass (bench_cold) and the problems written for the peer solver
(bench_peer): a fresh process makes its program at the first call and nothing after, and the
exported problem describes the posture posturegen finds."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pinocchio as pin

from posturegen.bench.cold import ColdReport, PeerReport, cold_table, run_cold
from posturegen.bench.peer import export_problem, write_problems
from posturegen.bench.reach import PLANNER_FAMILIES
from posturegen.solver.solve import solve


def test_a_fresh_process_makes_its_program_at_the_first_call_and_nothing_after(tmp_path):
    """Three never-seen problems in a fresh process with an empty cache: the first call makes
    the robot's program, the later ones make none, every posture is verified, and the problems
    were written for the peer."""
    peer = tmp_path / "problems.jsonl"
    report = run_cold("talos-box-collision", 3, seed=0, peer_file=peer)
    assert report.first_verified and report.verified == 2, report.failures
    assert report.later_structures == 0
    assert report.first_call_s > 0 and 0 < report.median_call_ms <= report.max_call_ms
    rows = [json.loads(line) for line in peer.read_text().splitlines()]
    assert [r["index"] for r in rows] == [0, 1, 2]
    assert {r["family"] for r in rows} == {"talos-box-collision"}


def test_the_exported_problem_is_the_posture_posturegen_finds(tmp_path):
    """Solve a planner query, export it: at the solution, each contact's link is at its
    exported pose and the task's point at its target (the names and frames the peer reads
    are the ones posturegen constrains); the avoided pairs are named links."""
    problem = next(iter(PLANNER_FAMILIES["talos-stances-collision"][1](1, 3)))
    result = solve(problem)
    assert result.success, result.message
    item = json.loads(write_problems(tmp_path / "p.jsonl", [export_problem(problem)]).read_text())
    model = problem.robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, result.q)
    for c in item["contacts"]:
        link = data.oMf[model.getFrameId(c["link"])]
        np.testing.assert_allclose(link.homogeneous, c["T_world_link"], atol=1e-6)
        assert np.dot(c["normal_world"], [0, 0, 1]) > 0.99  # the ground's normal, up
    for t in item["tasks"]:
        link = data.oMf[model.getFrameId(t["link"])]
        np.testing.assert_allclose(
            link.act(np.array(t["point_link"])), t["target_world"], atol=1e-6
        )
    names = {f.name for f in model.frames}
    assert item["self_pairs"] and all(set(p["links"]) <= names for p in item["self_pairs"])
    assert item["joints"] == [model.names[j] for j in range(2, model.njoints)]
    assert len(item["q_init"]) == model.nq and len(item["effort"]) == model.nv - 6


def test_the_cold_table_sets_the_peers_best_solver_beside_each_family():
    report = ColdReport(
        "talos-box-collision", 50, 1, 12.5, True, 49, 20.0, 30.0, 90.0, 15.0, 18, 0, 49, ()
    )
    peers = [
        PeerReport("talos-box-collision", "ipopt", 50, 40, 38, 900.0, 1200.0),
        PeerReport("talos-box-collision", "snopt", 50, 45, 44, 400.0, 700.0),
    ]
    lines = cold_table([report], peers)
    assert len(lines) == 3
    row = lines[2].split("|")[1:-1]
    assert row[0].strip() == "`talos-box-collision`" and row[2].strip() == "12.5"
    assert row[9].strip() == "snopt, 44/50, 400" and row[10].strip() == "20x"
    # a run of two solvers labels its rows; each still finds its family's peer
    labelled = dataclasses.replace(report, family="talos-box-collision [sqp]")
    row = cold_table([labelled], peers)[2].split("|")[1:-1]
    assert row[0].strip() == "`talos-box-collision [sqp]`" and row[10].strip() == "20x"
