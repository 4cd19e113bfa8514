"""Benchmark families and the comparison lines of ``posturegen bench``."""

from __future__ import annotations

import dataclasses

import pytest

from posturegen.bench.families import FAMILIES, FamilyReport, comparison_lines
from posturegen.cli import main


def _report(family: str, solve_ms: float, call_ms: float, iterations: float) -> FamilyReport:
    return FamilyReport(
        family=family,
        description="",
        n=1,
        successes=1,
        success_rate=1.0,
        median_solve_ms=solve_ms,
        min_solve_ms=solve_ms,
        max_solve_ms=solve_ms,
        median_call_ms=call_ms,
        median_iterations=iterations,
        variables=1,
        constraints=1,
        contact_rows=0,
        failures=(),
    )


def test_comparison_lines_give_the_variant_over_its_baseline():
    reports = [
        _report("talos-box-free", 5.0, 8.0, 12),
        _report("talos-box-collision", 11.0, 16.0, 18),
        _report("talos-near-body-collision", 1.0, 1.0, 1),  # its baseline did not run
    ]
    lines = comparison_lines(reports)
    assert lines == [
        "talos-box-collision / talos-box-free: solve 2.20x  call 2.00x  iterations 1.50x"
    ]
    assert comparison_lines(reports[:1]) == []


def test_bench_cli_prints_each_family_and_the_comparison(capsys):
    code = main(
        ["bench", "-n", "2", "--family", "talos-box-free", "--family", "talos-box-collision"]
    )
    out = capsys.readouterr().out.splitlines()
    assert code == 0
    assert out[0].startswith("talos-box-free ") and "success=100.0%" in out[0]
    assert out[1].startswith("talos-box-collision ") and "success=100.0%" in out[1]
    assert out[2].startswith("talos-box-collision / talos-box-free: solve ")


@pytest.mark.parametrize("pair", ["talos-near-body", "talos-box"])
def test_compared_families_are_the_same_problems(pair):
    """A comparison is fair only if both families generate the same problems but for the
    collision options."""
    free = list(FAMILIES[f"{pair}-free"][1](3, 0))
    coll = list(FAMILIES[f"{pair}-collision"][1](3, 0))
    for a, b in zip(free, coll, strict=True):
        assert [t.target.tolist() for t in a.tasks] == [t.target.tolist() for t in b.tasks]
        assert a.q_init.tolist() == b.q_init.tolist()
        assert [o.to_dict() for o in a.scene.obstacles] == [o.to_dict() for o in b.scene.obstacles]
        assert (
            a.collision_options is None
            or not dataclasses.asdict(a.collision_options)["self_collision"]
        )
        assert b.collision_options is not None


def test_compared_families_run_interleaved(monkeypatch):
    """Blocks of the baseline and of the variant in turn; other families alone."""
    from posturegen.bench import families as bench

    order = []
    step = bench._FamilyRun.step

    def recording(self, i):
        order.append((self.name, i))
        step(self, i)

    monkeypatch.setattr(bench._FamilyRun, "step", recording)
    monkeypatch.setattr(bench, "INTERLEAVE_BLOCK", 2)
    seen = []
    names = ["talos-box-collision", "talos-stand-reach", "talos-box-free"]
    reports = bench.run_families(names, n=3, done=lambda r: seen.append(r.family))
    assert [r.family for r in reports] == names
    assert sorted(seen) == sorted(names)
    assert order == [
        ("talos-box-free", 0),
        ("talos-box-free", 1),
        ("talos-box-collision", 0),
        ("talos-box-collision", 1),
        ("talos-box-free", 2),
        ("talos-box-collision", 2),
        ("talos-stand-reach", 0),
        ("talos-stand-reach", 1),
        ("talos-stand-reach", 2),
    ]
