"""``posturegen bench --family plan-...``: a plan family planned by the command, cold (an empty
cache) then warm, its row in the Markdown table and its numbers in the JSON."""

from __future__ import annotations

import json

import pytest

from posturegen.bench.plans import PLAN_FAMILIES, examples_dir, plan_command, run_plan_family
from posturegen.cli import main
from posturegen.errors import InputError
from posturegen.solver import codegen


def test_every_plan_family_has_its_scene(tmp_path):
    """A shipped scene's family names its robot; any other has its start and goal files."""
    for name, fam in PLAN_FAMILIES.items():
        cmd = plan_command(name, tmp_path)
        assert cmd[-4:] == ["--out", str(tmp_path), "--quiet", "--no-figures"]
        if fam.robot is None:
            assert (examples_dir() / f"{fam.source}.yaml").is_file(), name
            assert (examples_dir() / f"{fam.source}.goal.yaml").is_file(), name
        else:
            assert cmd[cmd.index("--robot") + 1] == fam.robot


def test_a_plan_family_runs_cold_then_warm(tmp_path, capsys):
    md, js = tmp_path / "plans.md", tmp_path / "plans.json"
    md.write_text("# results\n<!-- bench-plans:start -->\n<!-- bench-plans:end -->\ntail\n")
    code = main(
        ["bench", "--family", "plan-platform-hrp2", "--markdown", str(md), "--json", str(js)]
    )
    printed = capsys.readouterr().out
    assert code == 0 and "plan-platform-hrp2: reached, all verified" in printed
    (report,) = json.loads(js.read_text())
    for run in (report["cold"], report["compiling"], report["warm"]):
        assert run["reached"] and run["verified"] and run["stages"] >= 5
        assert run["wall_s"] > run["time"]["total_s"] > 0
        assert run["min_region_cm"] > 0 and run["min_cop_depth_cm"] > 0
    if codegen.compiler() is not None:  # the compiling run built the plan's structures in C
        assert report["compiling"]["time"]["build_s"] > report["warm"]["time"]["build_s"]
    text = md.read_text()
    assert text.startswith("# results\n") and text.endswith("tail\n")
    assert "| `plan-platform-hrp2` | HRP-2, a platform aside and turned | yes |" in text


def test_a_plan_family_with_another_family_is_refused(capsys):
    code = main(["bench", "--family", "plan-beam-talos", "--family", "talos-stand-reach"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "talos-stand-reach is not a plan family" in err[0]
    with pytest.raises(InputError, match="unknown plan family"):
        run_plan_family("plan-nope")
