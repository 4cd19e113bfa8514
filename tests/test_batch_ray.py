"""The Ray backend on a local Ray instance (ray is in the test extra: CI runs this module)."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import pytest
import ray
import yaml

import posturegen as pg
from posturegen.batch import run_batch
from posturegen.bench.families import talos_stand_reach
from posturegen.cli import main
from tests.batch_problems import FAR, killer, stand

TARGETS = [[0.32 + 0.03 * i, -0.32 + 0.02 * i, 0.85 + 0.03 * i] for i in range(5)]


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    """A local Ray instance of 2 CPUs for the module (the backend joins it)."""
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    yield
    ray.shutdown()


def _inputs(folder: Path) -> list:
    bad = stand(TARGETS[0])
    bad["tasks"][0]["frame"] = "right_paw"
    path = folder / "file.yaml"
    path.write_text(yaml.safe_dump(stand(TARGETS[1])))
    problems = [*(stand(t) for t in TARGETS), *talos_stand_reach(3, 7), path]
    return [*problems, stand(FAR, "far"), bad]


def test_ray_results_are_the_local_results(tmp_path):
    """The same problems on Ray and on the local pool (dicts, Problem objects, a file): the
    same success, status and q to 1e-9 (a failure and an input error among them)."""
    with pytest.warns(pg.ImplausibleValueWarning, match="far: "):
        local = pg.solve_many(_inputs(tmp_path), workers=2)
    with pytest.warns(pg.ImplausibleValueWarning, match="far: "):
        remote = pg.solve_many(_inputs(tmp_path), backend="ray")
    assert [r.success for r in local] == [True] * 9 + [False, False]
    for a, b in zip(local, remote, strict=True):
        assert type(a) is type(b) and a.success == b.success and a.status == b.status
        if isinstance(a, pg.Result):
            np.testing.assert_allclose(b.q, a.q, atol=1e-9, rtol=0)
        else:
            assert a.message == b.message and "tasks[0].frame" in a.message


def test_ray_actors_reuse_their_structures_and_survive_a_crash():
    """A problem that kills its actor is 'worker crashed'; Ray restarts the actor and the
    batch goes on. Each of the 2 actors builds the structure once."""
    inputs = [stand(t) for t in TARGETS] + [killer()] + [stand(t) for t in TARGETS]
    items = sorted(run_batch(inputs, workers=2, backend="ray"), key=lambda i: i.index)
    assert [i.result.success for i in items] == [True] * 5 + [False] + [True] * 5
    assert items[5].result.status == "worker crashed"
    for worker in {i.worker for i in items if i.worker}:
        mine = [i for i in items if i.worker == worker]
        assert sum(i.result.build_time_s > 0 for i in mine) == 1, worker


def test_bench_batch_table(capsys):
    """posturegen bench --batch: a row in-process, local 1 and 2 workers, Ray (on the module's
    instance: 2 CPUs); every problem
    verified, no structure built in the timed part, BLAS on one thread in every worker."""
    assert main(["bench", "--batch", "-n", "6"]) == 0
    out = capsys.readouterr().out
    rows = [
        [c.strip() for c in line.split("|")[1:-1]]
        for line in out.splitlines()
        if re.match(r"\| \w", line)
    ]
    table = {(r[0], r[1]): dict(zip(rows[0], r, strict=True)) for r in rows[1:]}
    rows_here = {("in-process", "1"), ("local", "1"), ("local", "2"), ("ray", "2")}
    assert rows_here <= set(table) and len(table) <= 5  # and local x os.cpu_count()
    for row in table.values():
        assert row["verified"] == "6/6" and row["builds timed"] == "0", row
        assert row["BLAS threads"] == "1" and float(row["postures/s"]) > 0, row
        assert 0 < float(row["workers' CPU share"]) <= 1.05, row
    assert table[("local", "1")]["speed-up"] == "1.00x"
    assert "load average" in out
