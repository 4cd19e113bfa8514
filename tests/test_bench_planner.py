"""The planner families (bench_reach), their fresh-process runs (bench_planner) and the
Markdown table of ``posturegen bench --markdown`` (bench_table)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posturegen.bench.planner import PassStats, PlannerReport
from posturegen.bench.reach import (
    MARGIN,
    MU,
    PLANNER_FAMILIES,
    STANCES_CALL_ITER,
    _ReachSampler,
    varied_stance,
)
from posturegen.bench.table import HEADER, results_table, write_markdown
from posturegen.cli import main
from posturegen.errors import InputError


def test_reach_targets_come_from_balanced_collision_free_configurations():
    sampler = _ReachSampler()
    model, data = sampler.robot.model, sampler.data
    rng = np.random.default_rng(3)
    targets = [sampler.target(rng) for _ in range(5)]
    assert len({tuple(t) for t in targets}) == 5
    q = sampler.robot.q_init.copy()
    q[sampler.index[0]] = 0.5  # torso turned, ...
    q[sampler.index[1]] = 0.5  # ... bent forward
    for k in sampler.index[2:]:
        q[k] = 0.0
    pin.centerOfMass(model, data, q)
    assert not sampler.ok(q)  # the right arm stretched out in front: not balanced
    assert sampler.ok(sampler.robot.q_init)
    bent = sampler.robot.q_init.copy()
    bent[model.joints[model.getJointId("arm_right_4_joint")].idx_q] = -2.0
    bent[model.joints[model.getJointId("arm_right_2_joint")].idx_q] = -0.1
    assert not sampler.ok(bent)  # the forearm into the side: proxies closer than held


def test_reach_families_are_the_same_problems_with_and_without_collision():
    free = list(PLANNER_FAMILIES["talos-reach-balance-free"][1](3, 0))
    coll = list(PLANNER_FAMILIES["talos-reach-balance-collision"][1](3, 0))
    for a, b in zip(free, coll, strict=True):
        assert a.tasks[0].target.tolist() == b.tasks[0].target.tolist()
        assert a.collision_options is None or not a.collision_options.self_collision
        assert b.collision_options.self_collision and b.collision_options.margin == MARGIN
        assert [c.mu for c in b.contacts] == [MU, MU]
        assert a.solver_options.max_call_iter is None is b.solver_options.max_call_iter
    for p in PLANNER_FAMILIES["talos-stances-collision"][1](2, 0):  # bounded as a planner's
        assert p.solver_options.max_call_iter == STANCES_CALL_ITER


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_varied_stances_are_in_their_ranges(seed):
    left, right, yaw_l, yaw_r = varied_stance(np.random.default_rng(seed))
    assert 0.15 <= left[1] - right[1] <= 0.24
    assert abs(left[0] - right[0]) <= 0.04 + 1e-12
    assert abs(yaw_l) <= 0.15 and abs(yaw_r) <= 0.15


def test_the_stances_family_draws_no_stance_whose_feet_intersect():
    """Seed 0 meets two such stances in its first 150 (narrow, toes turned in): drawn again."""
    from posturegen.bench.reach import stances_family
    from posturegen.collision.active_set import placed_blocked

    assert all(placed_blocked(p) is None for p in stances_family(150, 0))


def _stats(median: float, verified: int = 10) -> PassStats:
    return PassStats(10, verified, median, 2 * median, 3 * median, median / 2, 12, 20, 10, 0, ())


def test_the_markdown_table_has_a_row_per_family_and_replaces_only_its_markers(tmp_path):
    report = PlannerReport(
        "talos-reach-balance-free", "", True, _stats(9.0, 9), _stats(4.0), _stats(3.0)
    )
    lines = results_table("2026-12-02, a machine", True, [], [report])
    assert lines[0] == "Measured on 2026-12-02, a machine; generated C (`--jit`)."
    assert lines[2].count("|") == len(HEADER) + 1
    row = lines[-1].split(" | ")
    assert row[0] == "| `talos-reach-balance-free`" and row[2] == "10/10"
    assert row[4:7] == ["4.0", "8.0", "9.0 (18.0), 9/10 verified"]
    assert row[8] == "3.0 (6.0), 12 |"  # the nearest-start pass
    readme = tmp_path / "README.md"
    readme.write_text("# x\nbefore\n<!-- bench:start -->\nold\n<!-- bench:end -->\nafter\n")
    write_markdown(readme, lines)
    text = readme.read_text()
    assert text.startswith("# x\nbefore\n<!-- bench:start -->\nMeasured on")
    assert text.endswith("<!-- bench:end -->\nafter\n") and "old" not in text
    broken = tmp_path / "broken.md"
    broken.write_text("<!-- bench:start -->\n")
    with pytest.raises(InputError, match="bench:end"):
        write_markdown(broken, lines)


def test_bench_runs_a_planner_family_in_fresh_processes_and_writes_the_table(tmp_path, capsys):
    out = tmp_path / "bench.md"
    code = main(
        ["bench", "-n", "2", "--family", "talos-reach-balance-free", "--markdown", str(out)]
    )
    lines = capsys.readouterr().out.splitlines()
    assert code == 0
    assert lines[0].startswith("talos-reach-balance-free") and " first " in lines[0]
    assert " steady " in lines[1] and "verified=100.0%" in lines[1]
    assert " nearest " in lines[2] and "verified=100.0%" in lines[2]
    table = out.read_text().splitlines()
    assert table[-1].startswith("| `talos-reach-balance-free` | 2 | 2/2 |")


def test_bench_batch_refuses_a_planner_family(capsys):
    assert main(["bench", "--batch", "--family", "talos-stances-collision"]) == 2
    assert "--family" in capsys.readouterr().err
