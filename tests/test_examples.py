"""Every numbered script of examples/ runs, and what it shows holds."""

from __future__ import annotations

import runpy
from pathlib import Path

import numpy as np
import pytest

import posturegen as pg

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _main(name: str):
    """The example's ``main`` (run_path: the scripts' names start with digits)."""
    (path,) = EXAMPLES.glob(f"{name}_*.py")
    return runpy.run_path(str(path), run_name="example")["main"]


def test_every_example_is_tested():
    numbers = sorted(p.name[:2] for p in EXAMPLES.glob("[0-9][0-9]_*.py"))
    tested = sorted(n[len("test_example_") :] for n in globals() if n.startswith("test_example_"))
    assert numbers == tested


def test_example_01(tmp_path):
    result = _main("01")(tmp_path)
    assert result.success and (tmp_path / "posture.json").is_file()


def test_example_02():
    result, again = _main("02")()
    assert result.success and again.success
    np.testing.assert_allclose(result.q, again.q, atol=1e-6)
    assert [t["type"] for t in result.posture["tasks"]] == ["region", "axis", "gaze", "com"]


def test_example_03():
    diagnosis = _main("03")()
    assert "task 0" in diagnosis and "beyond reach" in diagnosis


def test_example_04():
    inclusive, support = _main("04")()
    assert not inclusive.success and support.success


def test_example_05():
    result = _main("05")()
    names = {c.name for c in result.verification.checks}
    assert result.success and any("meshes" in n for n in names)


def test_example_06():
    assert all(r.success for r in _main("06")())


def test_example_07():
    cold, warm = _main("07")(8)
    assert warm < cold


def test_example_08():
    answers = _main("08")(3, 2)
    assert isinstance(answers[-1], pg.BatchError) and "right_paw" in answers[-1].message
    assert all(a.success for a in answers[:-1])


def test_example_09(tmp_path):
    report = _main("09")(tmp_path)
    assert report.success and (tmp_path / "sequence.json").is_file()
    assert (tmp_path / "plan.html").is_file() and (tmp_path / "plan.png").is_file()


def test_example_10():
    result = _main("10")()
    assert result.success and result.posture["tasks"][1]["type"] == "hands_level"


@pytest.mark.parametrize("path", sorted((EXAMPLES / "problems").glob("*.yaml")), ids=str)
def test_every_example_problem_is_solved_and_verified(path):
    result = pg.solve(pg.load_problem(path))
    assert result.success, result.message
