"""Invalid input: one line on stderr naming the field, exit code 2, never a traceback."""

from __future__ import annotations

import copy
import math

import pytest
import yaml

from posturegen.cli import _demo_dir, main

BASE = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


def _edit(path: str, value):
    data = copy.deepcopy(BASE)
    keys = path.split(".")
    node = data
    for k in keys[:-1]:
        node = node[int(k)] if k.isdigit() else node[k]
    last = keys[-1]
    if value is _DELETE:
        del node[int(last) if last.isdigit() else last]
    elif last.isdigit():
        node[int(last)] = value
    else:
        node[last] = value
    return data


_DELETE = object()

CASES = [
    ("contacts", _DELETE, "contacts: missing"),
    ("bogus", 1, "problem.bogus: unknown key"),
    ("robot", "nao", "robot: unknown robot 'nao'"),
    ("contacts.0.robot_patch", "left_paw", "contacts[0].robot_patch"),
    ("contacts.0.surface", "ceiling", "contacts[0].surface"),
    ("contacts.0.type", "glued", "contacts[0].type"),
    ("contacts.0.position", [0.0], "contacts[0].position"),
    ("contacts.0.position", [5.0, 5.0], "contacts[0]: patch 'left_sole' does not overlap"),
    ("contacts.0.yaw", "north", "contacts[0].yaw"),
    ("contacts.1.name", "left_sole", "contacts[1].name"),
    ("tasks.0.frame", "no_such_frame", "tasks[0].frame"),
    ("tasks.0.target", [0.4, 0.1], "tasks[0].target"),
    ("tasks.0.target", [0.4, math.nan, 1.0], "tasks[0].target[1]"),
    ("tasks.0.type", "teleport", "tasks[0].type"),
    ("mu", -0.5, "mu: must be >= 0"),
    ("surfaces.0.vertices", [[0, 0], [1, 0], [0.2, 0.2], [0, 1]], "surfaces[0].vertices"),
    ("surfaces.0.vertices", [[0, 0], [1, 1], [1, 0], [0, 1]], "surfaces[0].vertices"),
    ("surfaces.0.vertices", [[0, 0], [1, 0], [2, 0]], "surfaces[0].vertices"),
    ("surfaces.0.vertices", [[0, 0], [1, 0]], "surfaces[0].vertices"),
    ("surfaces.0.vertices", [[0, 0], [1, 0], [1, 0], [0, 1]], "surfaces[0].vertices"),
    ("surfaces.0.rpy", [0, 0], "surfaces[0].rpy"),
    ("obstacles", [{"name": "wall", "box": [0.1, -2, 1]}], "obstacles[0].box"),
    ("options.initial", "crouching", "options.initial"),
    ("options.self_collision", "yes", "options.self_collision"),
    ("robot", {"urdf": "/nonexistent/robot.urdf"}, "robot.urdf"),
    ("robot", {"urdf": "x.urdf", "colour": "red"}, "robot.colour"),
]


@pytest.mark.parametrize(("path", "value", "expected"), CASES, ids=[c[2] for c in CASES])
def test_invalid_problem_is_one_clear_line(tmp_path, capsys, path, value, expected):
    problem = tmp_path / "problem.yaml"
    problem.write_text(yaml.safe_dump(_edit(path, value)))
    code = main(["solve", str(problem), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert expected in lines[0]
    assert not (tmp_path / "out" / "posture.json").exists()


def test_unreadable_yaml_and_missing_file(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: talos\ncontacts: [\n  - {robot_patch: left_sole")
    assert main(["solve", str(bad), "--out", str(tmp_path)]) == 2
    assert "invalid YAML" in capsys.readouterr().err
    assert main(["solve", str(tmp_path / "missing.yaml"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["verify", str(tmp_path / "missing.json")]) == 2
    assert main(["verify", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "invalid JSON" in err and len(err.strip().splitlines()) == 2


def test_not_a_mapping(tmp_path, capsys):
    bad = tmp_path / "list.yaml"
    bad.write_text("- 1\n- 2\n")
    assert main(["solve", str(bad), "--out", str(tmp_path)]) == 2
    assert "problem: expected a mapping" in capsys.readouterr().err


def test_unknown_demo(capsys):
    assert main(["demo", "moonwalk", "--out", "unused"]) == 2
    assert "unknown demo 'moonwalk'" in capsys.readouterr().err


def test_malformed_posture_file_is_one_line(tmp_path, capsys):
    assert main(["demo", "stand-reach", "--out", str(tmp_path), "--quiet"]) == 0
    import json

    data = json.loads((tmp_path / "posture.json").read_text())
    del data["contacts"][0]["surface"]
    (tmp_path / "broken.json").write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["verify", str(tmp_path / "broken.json")]) == 2
    err = capsys.readouterr().err
    assert "malformed posture file" in err and len(err.strip().splitlines()) == 1
