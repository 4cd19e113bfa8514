"""Batches on the local process pool: posturegen.solve_many, posturegen batch, the scheduler's
failure containment, the summary."""

from __future__ import annotations

import copy
import io
import json
import pickle
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import posturegen as pg
from posturegen.batch import jobs as J
from posturegen.batch.local import LocalBackend
from posturegen.batch.report import Summary, category, percentile
from posturegen.batch.schedule import chunks, run_jobs
from posturegen.batch.sources import read_sources
from posturegen.batch.worker import solve_job
from posturegen.bench.families import talos_stand_reach
from posturegen.cli import main
from tests.batch_problems import FAR, killer, stand
from tests.conftest import HRP2_URDF

TARGETS = [[0.3 + 0.03 * i, -0.3 + 0.02 * i, 0.9 + 0.02 * i] for i in range(6)]


def _hrp2_dict() -> dict:
    data = stand([0.35, -0.25, 0.75], "hrp2")
    data["robot"] = {
        "urdf": str(HRP2_URDF),
        "srdf": str(HRP2_URDF.with_suffix(".srdf")),
        "patches": "hrp2",
    }
    data["tasks"][0]["frame"] = "r_gripper"
    return data


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """Every kind of input: dicts, a file, Problem objects, a custom URDF's dict, a failure,
    an input error; and their in-process solves."""
    folder = tmp_path_factory.mktemp("problems")
    path = folder / "from-file.yaml"
    path.write_text(yaml.safe_dump(stand(TARGETS[0])))
    objects = list(talos_stand_reach(2, 3))
    bad = stand(TARGETS[1])
    bad["contacts"][0]["robot_patch"] = "left_paw"
    inputs = [stand(TARGETS[2]), path, objects[0], _hrp2_dict(), stand(FAR, "far"), bad]
    inputs += [objects[1], stand(TARGETS[3])]
    with pytest.warns(pg.ImplausibleValueWarning, match="far: tasks"):
        results = pg.solve_many(inputs, workers=2)
    with pytest.warns(pg.ImplausibleValueWarning):
        reference = [_solve_here(x) if k != 5 else None for k, x in enumerate(inputs)]
    return inputs, results, reference


def _solve_here(x: object) -> pg.Result:
    """pg.solve in this process, of a Problem, a file or a dict."""
    if isinstance(x, pg.Problem):
        return pg.solve(x)
    if isinstance(x, Path):
        return pg.solve(pg.load_problem(x))
    return pg.solve(pg.problem_from_dict(copy.deepcopy(x)))


def test_solve_many_answers_in_input_order_as_solve_does(mixed):
    """Each answer is the Result pg.solve gives in this process (the same q to 1e-9, the same
    status), in input order; the unknown patch is a one-line input error."""
    inputs, results, reference = mixed
    assert len(results) == len(inputs)
    for k, (got, want) in enumerate(zip(results, reference, strict=True)):
        if want is None:
            assert isinstance(got, pg.BatchError) and got.status == "input error"
            assert "contacts[0].robot_patch" in got.message and "left_paw" in got.message
            assert not got.success and "\n" not in got.message
            continue
        assert isinstance(got, pg.Result), k
        assert got.success == want.success and got.status == want.status, k
        np.testing.assert_allclose(got.q, want.q, atol=1e-9, rtol=0)
        assert got.posture["q"] == pytest.approx(want.posture["q"], abs=1e-9)
    assert [r.success for r in results] == [True, True, True, True, False, False, True, True]
    assert results[3].posture["robot"]["urdf"] == str(HRP2_URDF.resolve())


def test_results_carry_what_a_caller_needs(mixed):
    """q, torques, forces, timings and the posture dict come back; a Result pickles whole."""
    _, results, _ = mixed
    r = results[0]
    assert r.q.shape == (pg.load_robot("talos").model.nq,) and r.torques.shape == (32,)
    assert set(r.forces) == {"left_sole", "right_sole"} and r.solve_time_s > 0
    assert r.posture["success"] and r.verification.ok and r.iterations > 0
    back = pickle.loads(pickle.dumps(r))
    np.testing.assert_array_equal(back.q, r.q)
    assert back.verification.summary() == r.verification.summary()


def test_a_problem_on_a_urdf_robot_is_sent_as_its_dict():
    """A Problem object travels with its robot by name: one loaded from a URDF cannot, and its
    item says what to pass instead (its dict travels: test above)."""
    problem = pg.problem_from_dict(_hrp2_dict())
    (job,) = J.make_jobs([problem])
    assert job.problem is None and "pass its problem dict or file" in job.error
    item = solve_job(job)
    assert item.result.status == "input error" and not item.result.success


def test_a_crashed_worker_and_an_exception_fail_only_their_problem():
    """A problem that kills its worker is 'worker crashed' and the batch goes on (the pool is
    replaced); the others are verified."""
    inputs = [stand(TARGETS[0]), killer(), stand(TARGETS[1]), stand(TARGETS[2])]
    results = pg.solve_many(inputs, workers=2)
    assert [r.success for r in results] == [True, False, True, True]
    assert results[1].status == "worker crashed" and results[1].name == "killer"


def test_a_missing_file_is_its_problems_input_error(tmp_path):
    """The worker reads a file: a missing one is that problem's one-line input error."""
    missing = tmp_path / "missing.yaml"
    results = pg.solve_many([missing, stand(TARGETS[0])], workers=1)
    assert results[0].status == "input error" and results[0].name == "missing"
    assert results[0].message == f"{missing}: no such file (give the path of an existing file)"
    assert results[1].success


def test_an_exception_in_a_worker_is_its_problems_error():
    """Any exception while solving becomes that problem's BatchError (status error), one line
    with the exception's type."""

    class Raiser:
        def __reduce__(self):
            return int, ("not a number",)

    job = J.Job(0, "raiser", pickle.dumps(Raiser()))
    item = solve_job(job)
    assert item.result.status == "error" and item.result.message.startswith("ValueError: ")


def test_workers_build_a_structure_once_and_run_single_threaded_blas():
    """12 problems of one structure on 2 workers, one at a time: each worker builds the
    solver once (its first problem), and every OpenBLAS in it (numpy's, IPOPT's) runs one
    thread."""
    jobs = J.make_jobs([stand(t) for t in TARGETS * 2])
    pool = LocalBackend(2)
    try:
        items = list(run_jobs(pool, jobs, size=1))
        infos = pool.ready()
    finally:
        pool.close()
    assert all(i.result.success for i in items)
    builds = Counter(i.worker for i in items if i.result.build_time_s > 0)
    solved = Counter(i.worker for i in items)
    assert builds == Counter(dict.fromkeys(solved, 1)), (builds, solved)
    assert {info.worker for info in infos} == set(solved) or len(solved) < 2
    threads = [t for info in infos for _, t in info.blas_threads]
    assert len(threads) == 4 and set(threads) == {1}, infos  # two libraries in each worker


class _Fake:
    """A backend whose chunks fail when they hold a 'killer' job: ``pool`` like the local
    pool (a crash loses every chunk in flight), else like Ray (only that actor's)."""

    def __init__(self, slots: int, killers: set[int], pool: bool, order: list[int]) -> None:
        self.slots, self.killers, self.pool, self.order = slots, killers, pool, order
        self.sent: dict[int, list[J.Job]] = {}
        self.count = 0

    def submit(self, jobs):
        self.count += 1
        self.sent[self.count] = jobs
        return self.count

    def wait(self, handles):
        pick = handles[self.order[len(self.sent) % len(self.order)] % len(handles)]
        if any(j.index in self.killers for j in self.sent[pick]):
            lost = handles if self.pool else [pick]
            return [(h, RuntimeError("worker died")) for h in lost]
        items = [
            J.BatchItem(j.index, j.name, J.BatchError(j.name, "ok", ""), 0.0, "w")
            for j in self.sent[pick]
        ]
        return [(pick, items)]

    def crashed(self, exc):
        return True

    def recover(self):
        pass


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(1, 40),
    data=st.data(),
    slots=st.integers(1, 4),
    size=st.integers(1, 8),
    pool=st.booleans(),
)
def test_schedule_answers_each_job_once_and_blames_only_the_culprits(n, data, slots, size, pool):
    killers = data.draw(st.sets(st.integers(0, n - 1), max_size=n))
    order = data.draw(st.lists(st.integers(0, 7), min_size=1, max_size=6))
    backend = _Fake(slots, killers, pool, order)
    items = list(run_jobs(backend, J.make_jobs([{"name": f"p{i}"} for i in range(n)]), size))
    assert sorted(i.index for i in items) == list(range(n))
    for item in items:
        expected = "worker crashed" if item.index in killers else "ok"
        assert item.result.status == expected


@given(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=50), st.floats(0, 1))
def test_percentile_is_numpys_linear_one(values, q):
    assert percentile(values, q) == pytest.approx(np.percentile(values, 100 * q), abs=1e-9)


@given(st.lists(st.sampled_from(["a", "b", "batch", "a-2", "x"]), max_size=12))
def test_names_are_unique_and_never_the_index(names):
    jobs = J.make_jobs([{"name": name} for name in names])
    out = [j.name for j in jobs]
    assert len(set(out)) == len(out) and "batch" not in out
    assert [o.split("-")[0] for o in out] == [n.split("-")[0] for n in names]


@given(st.lists(st.integers(0, 9), max_size=30), st.integers(1, 8))
def test_chunks_keep_the_order(values, size):
    jobs = [J.Job(i, str(v), None) for i, v in enumerate(values)]
    cut = chunks(jobs, size)
    assert [j for c in cut for j in c] == jobs and all(1 <= len(c) <= size for c in cut)


def test_sources_read_files_folders_and_json_lines(tmp_path):
    (tmp_path / "b.yaml").write_text("robot: talos\n")
    (tmp_path / "a.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("")
    lines = io.StringIO('{"robot": "talos"}\n\n[1, 2]\n{oops\n')
    items = read_sources([str(tmp_path), "-"], lines)
    assert items[:2] == [tmp_path / "a.json", tmp_path / "b.yaml"]
    assert items[2] == {"robot": "talos", "name": "stdin-00001"}
    assert isinstance(items[3], J.Unreadable) and "stdin line 3: a JSON list" in items[3].message
    assert isinstance(items[4], J.Unreadable) and "line 4: invalid JSON" in items[4].message
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(pg.InputError, match="holds no problem file"):
        read_sources([str(empty)], io.StringIO(""))


def test_summary_counts_failures_by_cause(mixed):
    _, results, _ = mixed
    items = [J.BatchItem(k, f"p{k}", r, 0.01 * (k + 1), "w") for k, r in enumerate(results)]
    summary = Summary.of(items, 2.0, 2, "local")
    assert dict(summary.counts) == {
        "verified": 6,
        "IPOPT: Infeasible_Problem_Detected": 1,
        "input error": 1,
    }
    with pytest.warns(pg.ImplausibleValueWarning):
        far = pg.problem_from_dict(stand(FAR))
    assert category(pg.diagnose(far, results[4])) == "blocked: task"
    assert summary.rate == 4.0 and summary.verified == 6
    text = "\n".join(summary.lines())
    assert "median    45.0  p95    76.5" in text  # 10, 20 ... 80 ms


def test_cli_batch_writes_every_posture_and_the_index(tmp_path, monkeypatch, capsys):
    """A folder and a stdin stream: a posture file per problem (a failure's with its
    diagnosis), none for an unreadable line, batch.json in input order; exit 1 (a failure)."""
    folder = tmp_path / "problems"
    folder.mkdir()
    for k, target in enumerate(TARGETS[:3]):
        (folder / f"reach{k}.yaml").write_text(yaml.safe_dump(stand(target)))
    (folder / "far.yaml").write_text(yaml.safe_dump(stand(FAR)))
    stream = json.dumps(stand(TARGETS[4])) + "\nnot json\n"
    monkeypatch.setattr(sys, "stdin", io.StringIO(stream))
    out = tmp_path / "out"
    assert main(["batch", str(folder), "-", "--out", str(out), "--workers", "2"]) == 1
    captured = capsys.readouterr()
    assert "6/6" in captured.err and "postures/s" in captured.err
    assert "posturegen: warning: far: tasks[0].target" in captured.err
    assert "failed, blocked: task" in captured.out and "failed, input error" in captured.out
    index = json.loads((out / "batch.json").read_text())
    names = [p["name"] for p in index["problems"]]
    assert names == ["far", "reach0", "reach1", "reach2", "stdin-00001", "stdin-00002"]
    assert index["summary"]["counts"] == {"verified": 4, "blocked: task": 1, "input error": 1}
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["batch.json", "far.json", "reach0.json", "reach1.json", "reach2.json", "stdin-00001.json"]
    )
    far = json.loads((out / "far.json").read_text())
    assert not far["success"] and far["diagnosis"]["causes"][0]["kind"] == "task"
    assert main(["verify", str(out / "reach1.json")]) == 0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["batch", "missing.yaml", "--out", "o"], "missing.yaml: no such file or folder"),
        (["batch", "-", "--out", "o", "--address", "auto"], "address: an address is for the ray"),
        (["batch", "-", "--out", "o", "--workers", "0"], "workers: 0 workers"),
        (["batch", "-", "--out", "o", "--backend", "ray"], "backend: ray is not installed"),
    ],
)
def test_cli_batch_input_errors_are_one_line(argv, message, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "stdin", io.StringIO(json.dumps(stand(TARGETS[0])) + "\n"))
    monkeypatch.setitem(sys.modules, "ray", None)  # as if ray were not installed
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("posturegen: error: ") and message in err and err.count("\n") == 1
