"""Every code block of the README and of the documentation (docs/*.md) runs as written.

The fenced blocks are read from the pages at collection time, so a later edit of a page is
tested without touching this file:

- ``python``: run in order in one namespace per page (a later snippet uses an earlier one's
  variables), in a temporary folder that holds the page's problem file (its first YAML block
  with contacts; the README's for a page without one) as ``problem.yaml``;
- ``yaml``: a problem file (it has ``contacts``) is loaded by ``pg.load_problem`` from that
  ``problem.yaml``; a patch file (it has ``patches``) is loaded as the patches of the shipped
  robot whose URDF has its frames; any other block is a fragment of a problem file, each of
  its keys loaded as a problem file would (``robot``: ``load_robot``, relative paths under
  ``NAME/`` being a copy of the shipped robot NAME's model folder);
- ``json``: parsed;
- ``sh``: the two set-up commands, which CI runs itself (``.ci/run``): not run here;
- the docs' directives (``{toctree}``, ``{eval-rst}``, ``{literalinclude}``): Sphinx's, built
  by CI with warnings as errors.

A block of another language fails the test: decide how it is checked.
"""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml

import posturegen as pg
from posturegen.model.robot import BUNDLED, load_bundled, load_robot

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
CHECKED = {"python", "yaml", "json"}
# CI runs the sh ones, as the README says; text: the layout tree; Sphinx builds the directives
NOT_RUN = {"sh", "text", "{toctree}", "{eval-rst}", "{literalinclude}"}


@dataclass(frozen=True)
class Block:
    """One fenced code block: its language, its text and its first line in the README."""

    lang: str
    code: str
    line: int
    page: str = "README.md"

    @property
    def id(self) -> str:
        return f"{self.page}:{self.lang}-line{self.line}"


def readme_blocks(text: str, page: str = "README.md") -> list[Block]:
    """The fenced blocks (```lang ... ```) of a Markdown text, in order."""
    blocks, lang, start, lines = [], None, 0, []
    for i, line in enumerate(text.splitlines(), start=1):
        fence = re.match(r"^```\s*([\w+{}-]*)(?:\s.*)?$", line)  # a directive has arguments
        if fence is None:
            if lang is not None:
                lines.append(line)
            continue
        if lang is None:
            lang, start, lines = fence.group(1) or "(none)", i + 1, []
        else:
            blocks.append(Block(lang, "\n".join(lines) + "\n", start, page))
            lang = None
    if lang is not None:
        raise ValueError(f"{page}: the block opened at line {start - 1} is not closed")
    return blocks


BLOCKS_BY_PAGE = {
    str(p.relative_to(ROOT)): readme_blocks(p.read_text(encoding="utf-8"), str(p.relative_to(ROOT)))
    for p in PAGES
}
README_BLOCKS = BLOCKS_BY_PAGE["README.md"]
BLOCKS = [b for blocks in BLOCKS_BY_PAGE.values() for b in blocks]
PYTHON = [b for b in README_BLOCKS if b.lang == "python"]


def _params(lang: str) -> list[Any]:
    return [pytest.param(b, id=b.id) for b in BLOCKS if b.lang == lang]


def _problem_block(page: str = "README.md") -> Block:
    """A page's problem file: its first YAML block with contacts (the README's when it has
    none)."""
    for b in BLOCKS_BY_PAGE[page]:
        if b.lang == "yaml" and isinstance(d := yaml.safe_load(b.code), dict) and "contacts" in d:
            return b
    if page != "README.md":
        return _problem_block()
    raise AssertionError("README.md has no problem file (a yaml block with contacts)")


def test_readme_has_the_blocks_it_promises():
    langs = {b.lang for b in BLOCKS}
    assert langs <= CHECKED | NOT_RUN, f"blocks of {langs - CHECKED - NOT_RUN}: check them here"
    assert len(PYTHON) >= 2 and _problem_block() is not None
    sh = [b for b in README_BLOCKS if b.lang == "sh"]
    assert len(sh) == 1 and len(sh[0].code.strip().splitlines()) == 2  # the two commands


def test_the_readme_is_short():
    """At most about 200 lines (the reference is in docs/; Sphinx, run with -W by
    tests/test_docs_build.py, fails on a page that no toctree links)."""
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 200


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory) -> dict[str, Path]:
    """Per page, a folder with its problem file as problem.yaml."""
    out = {}
    for page in BLOCKS_BY_PAGE:
        d = tmp_path_factory.mktemp(page.replace("/", "-"))
        (d / "problem.yaml").write_text(_problem_block(page).code)
        out[page] = d
    return out


@pytest.fixture()
def workdir(workdirs, request) -> Path:
    block = request.node.callspec.params.get("block")
    return workdirs[block.page if block is not None else "README.md"]


class PythonSession:
    """A page's Python blocks run in order, once each, in one namespace."""

    def __init__(self, cwd: Path, blocks: list[Block]) -> None:
        self.cwd = cwd
        self.blocks = blocks
        self.namespace: dict[str, Any] = {"__name__": "__readme__"}
        self.outcomes: dict[int, BaseException | None] = {}

    def run_through(self, k: int, monkeypatch: pytest.MonkeyPatch) -> None:
        """Run blocks 0..k that have not run (in ``cwd``); raise block k's exception."""
        monkeypatch.chdir(self.cwd)
        for i in range(k + 1):
            block = self.blocks[i]
            if i not in self.outcomes:
                try:
                    exec(
                        compile(block.code, f"{block.page}:{block.line}", "exec"),
                        self.namespace,
                    )
                    self.outcomes[i] = None
                except Exception as exc:  # noqa: BLE001 (reported by its own test)
                    self.outcomes[i] = exc
            if i < k and self.outcomes[i] is not None:
                pytest.fail(f"the earlier block at {block.page}:{block.line} failed")
        if (exc := self.outcomes[k]) is not None:
            raise exc


@pytest.fixture(scope="module")
def sessions(workdirs) -> dict[str, PythonSession]:
    return {
        page: PythonSession(workdirs[page], [b for b in blocks if b.lang == "python"])
        for page, blocks in BLOCKS_BY_PAGE.items()
    }


@pytest.mark.parametrize("block", _params("python"))
def test_python_block_runs(block, sessions, monkeypatch):
    session = sessions[block.page]
    session.run_through(session.blocks.index(block), monkeypatch)
    if block is PYTHON[0]:  # the first snippet solves the README's problem and writes it
        assert session.namespace["result"].success
        assert (session.cwd / "out" / "posture.json").is_file()


def _copy_robot_models(root: Path, fragment: Any) -> None:
    """For every relative path ``NAME/...`` or ``DIR/NAME/...`` in a fragment whose NAME is a
    shipped robot: that robot's model folder copied to ``root/.../NAME``."""
    paths = re.findall(r"[\w./-]+\.(?:urdf|srdf)", json.dumps(fragment))
    for p in paths:
        parts = Path(p).parts
        for i, name in enumerate(parts[:-1]):
            if name in BUNDLED and not (root / Path(*parts[: i + 1])).exists():
                src = load_bundled(name).urdf.parent
                shutil.copytree(src, root / Path(*parts[: i + 1]))


def _robot_with_frames(frames: set[str]) -> str:
    """The first shipped robot whose model has every frame."""
    for name in BUNDLED:
        model = load_bundled(name).model
        if all(model.existFrame(f) for f in frames):
            return name
    raise AssertionError(f"no shipped robot has the frames {sorted(frames)}")


@pytest.mark.parametrize("block", _params("yaml"))
def test_yaml_block_loads(block, workdir, monkeypatch):
    data = yaml.safe_load(block.code)
    assert isinstance(data, dict), "a YAML block of the README is a mapping"
    monkeypatch.chdir(workdir)
    if "contacts" in data:  # a problem file
        own = block == _problem_block(block.page)
        problem = pg.load_problem("problem.yaml" if own else _write(block))
        assert problem.summary()
    elif "patches" in data:  # a patch file
        frames = {p["frame"] for p in data["patches"].values()}
        shipped = load_bundled(_robot_with_frames(frames))
        path = _write(block, "patches.yaml")
        robot = load_robot(
            {"urdf": str(shipped.urdf), "srdf": str(shipped.srdf), "patches": str(path)}
        )
        assert set(robot.patches) == set(data["patches"])
        if "initial" in data:
            assert robot.q_init.shape == (robot.model.nq,)
    else:  # a fragment of a problem file: each key as a problem file loads it
        assert set(data) <= {"robot"}, f"fragment keys {set(data)}: check them here"
        _copy_robot_models(workdir, data)
        robot = load_robot(data["robot"], workdir)
        assert robot.patches


def _write(block: Block, name: str | None = None) -> Path:
    path = Path(name or f"block-{block.line}.yaml")
    path.write_text(block.code)
    return path


@pytest.mark.parametrize("block", _params("json"))
def test_json_block_parses(block):
    data = json.loads(block.code)
    assert isinstance(data, dict | list)
