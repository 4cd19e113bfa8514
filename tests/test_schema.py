"""The problem file's JSON Schema (posturegen.io.schema, ``posturegen schema``)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml

from posturegen.cli import main
from posturegen.climb.scenes import SCENES, scene
from posturegen.io.problem_file import read_yaml
from posturegen.io.schema import problem_schema, shipped_schema_path, validate

ROOT = Path(__file__).resolve().parent.parent
PROBLEMS = sorted((ROOT / "examples" / "problems").glob("*.yaml"))
PLAN_STARTS = [
    p
    for p in sorted((ROOT / "examples" / "plans").glob("*.yaml"))
    if ".goal." not in p.name and ".rules." not in p.name
]
DEMOS = sorted((ROOT / "src" / "posturegen" / "data" / "demos").glob("*.yaml"))


def test_the_shipped_schema_is_the_generated_one():
    """Regenerate it with: posturegen schema -o src/posturegen/data/problem.schema.json
    (in a process where no task of a user's own is registered)."""
    assert json.loads(shipped_schema_path().read_text()) == problem_schema(user_tasks=False)


@pytest.mark.parametrize("path", PROBLEMS + DEMOS + PLAN_STARTS, ids=lambda p: p.name)
def test_every_example_and_demo_problem_fits_the_schema(path):
    assert validate(read_yaml(path)) == []


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_shipped_scene_stage_fits_the_schema(name):
    """Each stage's contacts (those not kept from the stage before) and tasks, and the
    scene's own keys."""
    seq = scene(name)
    schema = problem_schema()
    top = {k: seq[k] for k in ("robot", "mu", "surfaces", "obstacles", "costs") if k in seq}
    for i, stage in enumerate(seq["stages"]):
        contacts = [c for c in stage["contacts"] if c.get("type") != "keep"]
        if not contacts:
            continue
        data = {**top, "contacts": contacts, "tasks": stage.get("tasks", [])}
        if stage.get("options"):
            data["options"] = stage["options"]
        assert validate(data, schema) == [], f"{name} stage {i}"


@pytest.mark.parametrize(
    ("edit", "where"),
    [
        (lambda d: d["tasks"][0].update(targt=[0, 0, 1]), "tasks[0]"),
        (lambda d: d["tasks"][0].update(type="positon"), "tasks[0]"),
        (lambda d: d["contacts"][0].update(yaw="zero"), "contacts[0]"),
        (lambda d: d["options"].update(self_colision=True), "options"),
        (lambda d: d.pop("contacts"), "problem"),
    ],
)
def test_a_broken_file_does_not_fit_and_says_where(edit, where):
    data = copy.deepcopy(read_yaml(PROBLEMS[0]))
    data.setdefault("options", {})
    edit(data)
    errors = validate(data)
    assert errors and errors[0].startswith(where), errors


def test_the_command_prints_the_schema_and_validates(tmp_path, capsys):
    out = tmp_path / "schema.json"
    assert main(["schema", "-o", str(out)]) == 0
    assert json.loads(out.read_text())["title"] == "posturegen problem file"
    bad = tmp_path / "bad.yaml"
    data = read_yaml(PROBLEMS[0])
    data["mu"] = -1
    bad.write_text(yaml.safe_dump(data))
    assert main(["schema", "--validate", str(PROBLEMS[0]), str(bad)]) == 2
    captured = capsys.readouterr()
    assert "ok" in captured.out and f"{bad}: mu:" in captured.err
