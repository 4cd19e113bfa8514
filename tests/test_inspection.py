"""``posturegen inspect``: every block of the program, collision rows included."""

from __future__ import annotations

import copy
import importlib
import re

import yaml

from posturegen._cache import BoundedCache
from posturegen.cli import _demo_dir, main
from posturegen.io.problem_file import problem_from_dict
from posturegen.solver.inspection import describe, initial_collision_term, solver_line
from posturegen.solver.sqp import native

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
# 1.4 cm from the right hand's proxies at the initial posture: its sphere-box pairs are near
BOX = {"name": "box", "box": [0.2, 0.2, 0.2], "position": [0.32, -0.35, 0.75]}
solve_module = importlib.import_module("posturegen.solver.solve")


def _with(obstacles: list, self_collision: bool = False) -> dict:
    data = copy.deepcopy(STAND)
    data["obstacles"] = obstacles
    data["options"]["self_collision"] = self_collision
    return data


def _rows(text: str) -> dict[str, int]:
    return {m[1]: int(m[2]) for m in re.finditer(r"^  (\S+): (\d+)$", text, re.MULTILINE)}


def test_inspect_shows_the_collision_blocks(tmp_path, capsys):
    plain, boxed = tmp_path / "plain.yaml", tmp_path / "box.yaml"
    plain.write_text(yaml.safe_dump(_with([])))
    boxed.write_text(yaml.safe_dump(_with([BOX], self_collision=True)))
    assert main(["inspect", str(plain)]) == 0
    without = capsys.readouterr().out
    assert main(["inspect", str(boxed)]) == 0
    with_box = capsys.readouterr().out
    rows = _rows(with_box)
    assert rows["collision.env"] > 0 and rows["collision.self"] > 0
    total = int(re.search(r"^constraints: (\d+)$", with_box, re.MULTILINE)[1])
    before = int(re.search(r"^constraints: (\d+)$", without, re.MULTILINE)[1])
    assert total == before + rows["collision.env"] + rows["collision.self"]
    assert "obstacle 'box'" in with_box and "the solid under surface 'ground'" in with_box
    assert "parameters of one program" in with_box
    assert "collision" not in without


def test_the_rows_shown_are_those_of_the_first_ipopt_run(monkeypatch):
    """The active-set loop's first program has exactly the collision blocks inspect shows."""
    data = _with([BOX], self_collision=True)
    problem = problem_from_dict(data)
    shown = _rows(describe(problem))
    # no pairs from earlier solves
    monkeypatch.setattr(solve_module, "_LEARNED", BoundedCache("learned", 64))
    first: list[dict[str, int]] = []
    real = solve_module.run_nlp

    def spy(p: object, *args: object, **kwargs: object) -> object:
        runs = real(p, *args, **kwargs)
        if not first:
            first.append({n: s.stop - s.start for n, s in runs[-1].compiled.g_index.items()})
        return runs

    monkeypatch.setattr(solve_module, "run_nlp", spy)
    solve_module.solve(problem_from_dict(data))
    assert first[0] == {n: k for n, k in shown.items() if n in first[0]}
    assert first[0]["collision.env"] == shown["collision.env"]
    assert first[0]["collision.self"] == shown["collision.self"]


def test_no_collision_rows_without_avoidance():
    problem = problem_from_dict(_with([]))
    assert initial_collision_term(problem) is None
    assert describe(problem) == problem.summary() + "\n" + solver_line(problem.solver_options)


def test_inspect_says_which_solver_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("POSTUREGEN_SOLVER", raising=False)
    path = tmp_path / "plain.yaml"
    data = _with([])
    path.write_text(yaml.safe_dump(data))
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out  # the default
    loop = "C" if native.available() else "Python"
    assert f"solver: auto: posturegen's SQP ({loop} loop, QP: daqp), then IPOPT from" in out
    data["options"]["solver"] = {"method": "ipopt"}
    path.write_text(yaml.safe_dump(data))
    assert main(["inspect", str(path)]) == 0
    assert "solver: ipopt: IPOPT" in capsys.readouterr().out
    monkeypatch.setenv("POSTUREGEN_SOLVER", "sqp")
    data["options"]["solver"] = {"qp": "proxsuite"}
    path.write_text(yaml.safe_dump(data))
    assert main(["inspect", str(path)]) == 0
    assert f"solver: sqp: posturegen's SQP ({loop} loop, QP: proxsuite)" in capsys.readouterr().out
