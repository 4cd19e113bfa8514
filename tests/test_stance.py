"""The README's climb-step snippet, exactly as written, on the README's problem file."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

import posturegen as pg

README = Path(__file__).resolve().parents[1] / "README.md"


def _block(language: str, contains: str) -> str:
    """The README's one code block of ``language`` that contains ``contains``."""
    blocks = re.findall(rf"```{language}\n(.*?)```", README.read_text(), re.S)
    found = [b for b in blocks if contains in b]
    assert len(found) == 1, f"{len(found)} {language} blocks contain {contains!r}"
    return found[0]


def test_readme_next_stance_snippet(tmp_path, monkeypatch):
    """Both feet fixed, then `fix="right_sole", release="left_sole"`: the right sole, already
    fixed, stays where it is and Talos stands on it alone, verified."""
    (tmp_path / "problem.yaml").write_text(_block("yaml", "contacts:"))
    monkeypatch.chdir(tmp_path)
    problem = pg.load_problem("problem.yaml")
    result = pg.solve(problem)
    assert result.success, result.message
    scope = {"pg": pg, "problem": problem, "result": result}
    exec(_block("python", "next_problem("), scope)  # noqa: S102 - the README's own snippet
    nxt, result2 = scope["nxt"], scope["result2"]
    assert [c.name for c in nxt.contacts] == ["right_sole"]
    right = problem.contacts[[c.name for c in problem.contacts].index("right_sole")]
    assert nxt.contacts[0] is right
    assert result2.success, result2.message
    assert result2.forces["right_sole"]
    total = sum(f.force for f in result2.forces["right_sole"])
    np.testing.assert_allclose(
        total, [0, 0, problem.robot.weight], atol=1e-5 * problem.robot.weight
    )
