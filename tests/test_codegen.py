"""Generated C for the program's functions: keyed by the program's content, cached on disk,
built in the background after reuse, identical to CasADi's virtual machine."""

from __future__ import annotations

import copy
import dataclasses
import inspect
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from posturegen import _lifeline, problem_from_dict, solve
from posturegen._cache import clear_caches
from posturegen.cli import _demo_dir, main
from posturegen.collision import native
from posturegen.errors import InputError
from posturegen.solver import codegen
from posturegen.solver import compile as compile_module
from posturegen.solver.compile import _CACHE, symbolic

STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())
needs_cc = pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")


def _problem(mode: str, target: list[float] | None = None, torque_cost: bool = False):
    """The stand-reach demo; ``torque_cost`` adds a cost term: another program."""
    data = copy.deepcopy(STAND)
    if target is not None:
        data["tasks"][0]["target"] = target
    if torque_cost:
        data["costs"] = {"torques": 1e-3}
    p = problem_from_dict(data)
    p.solver_options = dataclasses.replace(p.solver_options, codegen=mode)
    return p


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """A fresh library cache for this module; the in-memory solver cache emptied before and
    after."""
    mp = pytest.MonkeyPatch()
    path = tmp_path_factory.mktemp("cache")
    mp.setenv("POSTUREGEN_CACHE", str(path))
    _CACHE.clear()
    yield path
    codegen.wait()
    native.wait()
    _CACHE.clear()
    mp.undo()


def test_library_key_follows_the_program_not_its_parameters():
    a = _problem("off").compile()
    b = _problem("off", target=[0.35, -0.45, 1.0]).compile()
    c = _problem("off", torque_cost=True).compile()
    assert a is b  # one structure
    key = codegen.library_key(a.nlp)
    assert key == codegen.library_key(b.nlp)
    assert key != codegen.library_key(c.nlp)  # another program: another library


def test_library_key_covers_the_compiler_flags(monkeypatch):
    nlp = _problem("off").compile().nlp
    key = codegen.library_key(nlp)
    monkeypatch.setattr(codegen, "HOT_FLAGS", ("-O2",))
    assert codegen.library_key(nlp) != key


def test_library_key_covers_the_code_of_hand_built_derivatives(monkeypatch):
    """Programs with BlockDerivatives add the package's source digest to their key (their
    derivative functions are built only for a solver made from the expressions)."""
    from posturegen.solver import fingerprint as F

    plain = symbolic(_problem("off"))
    assert plain.derivative_key == "" and plain.derivative_functions == {}
    nlp = plain.function
    key = codegen.library_key(nlp, "abc")
    assert key != codegen.library_key(nlp) and key == codegen.library_key(nlp, "abc")
    assert F.source_digest() == F.source_digest()  # cached, stable within a process


def test_modes():
    assert codegen.resolve_mode("off") == "off"
    with pytest.raises(InputError, match="SolverOptions.codegen: unknown codegen mode 'fast'"):
        codegen.resolve_mode("fast")


def test_a_bad_codegen_variable_is_a_one_line_error(monkeypatch, tmp_path, capsys):
    """$POSTUREGEN_CODEGEN=fast: one line naming the variable and the allowed values, exit 2."""
    monkeypatch.setenv("POSTUREGEN_CODEGEN", "fast")
    with pytest.raises(InputError) as err:
        codegen.resolve_mode(None)
    assert str(err.value) == (
        "$POSTUREGEN_CODEGEN: unknown codegen mode 'fast' "
        "(use one of: auto, sync, background, cached, off)"
    )
    _CACHE.clear()  # a structure compiled before would not look at the variable
    code = main(["solve", str(_demo_dir() / "stand-reach.yaml"), "--out", str(tmp_path)])
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err_lines) == 1 and "$POSTUREGEN_CODEGEN" in err_lines[0]


@needs_cc
def test_auto_compiles_before_the_first_solve_and_matches_the_virtual_machine(cache):
    """Mode auto: a structure's first solve waits for its library and runs it, the re-check's
    outputs too (not the virtual machine's expressions); the same iterates as the virtual
    machine."""
    reference = solve(_problem("off"))
    builds = len(codegen.BUILDS)
    first = _problem("auto")
    r1 = solve(first)
    assert first.compile().library and len(codegen.BUILDS) == builds + 1
    assert first.compile().outputs.class_name() == "External"
    assert not codegen.BUILDS[-1].background
    r2 = solve(_problem("auto"))
    assert len(codegen.BUILDS) == builds + 1  # built once
    for r in (r1, r2):
        assert r.success and r.generated_c, r.message
        assert r.iterations == reference.iterations
        assert np.max(np.abs(r.q - reference.q)) <= 1e-9
        scale = max(1.0, float(np.max(np.abs(reference.torques))))
        assert np.max(np.abs(r.torques - reference.torques)) <= 1e-9 * scale


@needs_cc
def test_background_builds_at_the_first_use_while_the_virtual_machine_solves(cache, monkeypatch):
    """Mode background: the first solve runs the virtual machine and queues the build; once
    built, the next solve switches to the library, with the same posture."""
    monkeypatch.setattr(codegen, "HOT_FLAGS", ("-O0", "-DBACKGROUND"))  # a key of its own
    _CACHE.clear()
    reference = solve(_problem("off", torque_cost=True))
    first = _problem("background", torque_cost=True)
    r1 = solve(first)
    compiled = first.compile()
    assert not r1.generated_c
    assert (
        compiled.library_key in codegen.pending()
        or codegen.library_path(compiled.library_key).is_file()
    )
    assert codegen.wait(timeout=300)
    r2 = solve(_problem("background", torque_cost=True))
    assert compiled.library and r2.generated_c
    for r in (r1, r2):
        assert r.success and r.iterations == reference.iterations
        assert np.max(np.abs(r.q - reference.q)) <= 1e-9
    assert codegen.BUILDS[-1].background


@needs_cc
def test_second_build_loads_from_disk_without_compiling(cache, monkeypatch):
    _problem("sync").compile()  # built by the previous test or now
    _CACHE.clear()  # as in a new process

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(codegen, "_generate", no_compiler)
    monkeypatch.setattr(codegen, "_compile", no_compiler)
    p = _problem("sync", target=[0.35, -0.45, 1.0])
    compiled = p.compile()
    assert compiled.library
    r = solve(p)
    assert r.success, r.message
    assert compiled.library


@needs_cc
def test_cached_runs_a_library_on_disk_and_compiles_nothing(cache, monkeypatch):
    """Mode cached (the planner's): the stand-reach library on disk is run; a structure
    without one (other compiler flags: another key) runs the virtual machine at every use, and
    no build starts."""
    _problem("sync").compile()  # on disk (built by an earlier test or now)
    _CACHE.clear()  # as in a new process

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled")

    monkeypatch.setattr(codegen, "_generate", no_compiler)
    monkeypatch.setattr(codegen, "_compile", no_compiler)
    r = solve(_problem("cached"))
    assert r.success and r.generated_c, r.message
    monkeypatch.setattr(codegen, "HOT_FLAGS", ("-O0", "-DCACHED"))  # no library under this key
    _CACHE.clear()
    for _ in range(3):
        r = solve(_problem("cached"))
        assert r.success and not r.generated_c, r.message
    assert not codegen.pending()


def _declaring(monkeypatch) -> list[int]:
    """Count the declarations of symbolic programs from now on."""
    calls: list[int] = []
    declare = compile_module._declare
    monkeypatch.setattr(compile_module, "_declare", lambda p: (calls.append(1), declare(p))[1])
    return calls


@needs_cc
def test_a_structure_found_by_its_fingerprint_is_not_declared(cache, monkeypatch):
    """In a new process (caches cleared), a structure whose library and layout are on disk is
    solved from them without its symbolic program: the same layout, the same posture."""
    first = _problem("sync")
    built = first.compile()  # built by an earlier test or now
    reference = solve(first)
    assert built.library and codegen.layout_path(built.library_key).is_file()
    clear_caches()
    calls = _declaring(monkeypatch)
    p = _problem("sync")
    compiled = p.compile()
    assert calls == [] and compiled.library and compiled.library_key == built.library_key
    for name in ("x_index", "p_index", "g_index", "cost_names"):
        assert getattr(compiled, name) == getattr(built, name)
    for name in ("lbx", "ubx", "lbg", "ubg"):
        assert np.array_equal(getattr(compiled, name), getattr(built, name))
    r = solve(p)
    assert calls == [] and r.success and r.iterations == reference.iterations
    assert np.array_equal(r.q, reference.q) and np.array_equal(r.torques, reference.torques)


@needs_cc
def test_a_layout_that_disagrees_with_its_library_is_not_used(cache, monkeypatch):
    """A layout beside the library with one constraint row too few: the structure is
    declared (and solves) as without one."""
    key = _problem("sync").compile().library_key
    path = codegen.layout_path(key)
    saved = path.read_bytes()
    data = dict(np.load(path))
    data["lbg"], data["ubg"] = data["lbg"][:-1], data["ubg"][:-1]
    try:
        with path.open("wb") as f:
            np.savez(f, **data)
        clear_caches()
        calls = _declaring(monkeypatch)
        p = _problem("sync")
        compiled = p.compile()
        assert calls == [1] and compiled.library and compiled.n_g == len(data["lbg"]) + 1
        assert solve(p).success
        path.unlink()
        clear_caches()
        assert _problem("sync").compile().library and calls == [1, 1]  # no layout: declared
    finally:
        path.write_bytes(saved)
        clear_caches()


@needs_cc
def test_sync_builds_before_the_first_solve(cache, monkeypatch):
    monkeypatch.setattr(codegen, "HOT_FLAGS", ("-O0",))  # another key, and a quick build
    _CACHE.clear()
    builds = len(codegen.BUILDS)
    p = _problem("sync")
    r = solve(p)
    assert p.compile().library
    assert r.success, r.message
    assert len(codegen.BUILDS) == builds + 1 and not codegen.BUILDS[-1].background
    assert codegen.BUILDS[-1].size == codegen.library_path(p.compile().library_key).stat().st_size


def test_without_a_compiler_the_virtual_machine_solves(cache, monkeypatch):
    monkeypatch.setattr(codegen, "compiler", lambda: None)
    assert codegen.resolve_mode("sync") == "off"
    _CACHE.clear()
    p = _problem("sync", torque_cost=True)
    compiled = p.compile()
    assert compiled.library_key is None and not compiled.library
    assert solve(p).success


def test_a_failed_build_falls_back_to_the_virtual_machine(cache, monkeypatch):
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    monkeypatch.setattr(codegen, "_FAILED", set())
    _CACHE.clear()
    p = _problem("sync", torque_cost=True)
    with pytest.warns(UserWarning, match="C build failed"):
        compiled = p.compile()
    assert not compiled.library and compiled.library_key in codegen._FAILED
    assert not codegen.library_path(compiled.library_key).exists()
    assert solve(p).success


def test_prune_keeps_the_most_recently_used_libraries(tmp_path, monkeypatch):
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    root = codegen.cache_dir()
    root.mkdir(parents=True)
    for age, name in enumerate(["new", "mid", "old"]):  # 3 MB each, older and older
        path = root / f"{name}.so"
        path.write_bytes(b"\0" * (3 << 20))
        os.utime(path, (1e9 - age * 100, 1e9 - age * 100))
    monkeypatch.setattr(codegen, "MAX_CACHE_BYTES", 7 << 20)
    codegen._prune()
    assert sorted(p.stem for p in root.glob("*.so")) == ["mid", "new"]


# ----------------------------------------------------------------- compilers die with us
CHILD = """
import json, os, sys, time, uuid
from posturegen._cache import clear_caches
from posturegen import _lifeline
from posturegen.solver import codegen
from posturegen.solver import compile as compile_module
from posturegen.cli import _demo_dir
from posturegen.io.problem_file import load_problem

codegen.HOT_FLAGS = ("-O2",)  # the Hessian then compiles for minutes: it cannot end first
compiled = load_problem(_demo_dir() / "stand-reach.yaml").compile()
key = codegen.library_key(compiled.nlp, uuid.uuid4().hex)  # never built: a real compile
codegen.build_in_background(key, compiled.sources())
t0 = time.time()
while time.time() - t0 < 120:  # until a compiler proper (cc1) runs in one of the groups
    groups = _lifeline.running()
    if any(comm == "cc1" for comm, _ in live_in(groups)):
        break
    time.sleep(0.02)
print(json.dumps({"groups": groups, "live": live_in(groups)}), flush=True)
if sys.argv[1] == "exit":
    sys.exit(0)
time.sleep(120)  # until the test sends a signal
"""


def _live_in(groups: list[int]) -> list[tuple[str, int]]:
    """(command, pid) of the processes that are not zombies, in the process groups."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        comm = text[text.index("(") + 1 : text.rindex(")")]
        state, _, pgrp = text[text.rindex(")") + 2 :].split()[:3]
        if state != "Z" and int(pgrp) in groups:
            out.append((comm, int(stat.parent.name)))
    return out


def _child_build(how: str, tmp_path: Path) -> tuple[subprocess.Popen, dict]:
    """A Python process that starts a background build of the stand-reach demo's program and
    reports its compilers' process groups once a cc1 runs; it then exits (``exit``) or waits
    for a signal."""
    script = "from pathlib import Path\n" + inspect.getsource(_live_in) + CHILD
    script = script.replace("def _live_in", "def live_in")
    env = {**os.environ, "POSTUREGEN_CACHE": str(tmp_path)}
    proc = subprocess.Popen(
        [sys.executable, "-c", script, how], stdout=subprocess.PIPE, text=True, env=env
    )
    line = proc.stdout.readline()
    if not line:
        proc.stdout.close()
        pytest.fail(f"the child printed nothing (exit {proc.wait()})")
    report = json.loads(line)
    if not any(comm == "cc1" for comm, _ in report["live"]):  # it was compiling
        proc.kill()
        proc.wait()
        proc.stdout.close()
        pytest.fail(f"no cc1 ran: {report}")
    return proc, report


def _gone(groups: list[int], timeout: float = 5.0) -> list[tuple[str, int]]:
    """The processes still alive in the groups after at most ``timeout`` [s]."""
    t0 = time.monotonic()
    while (live := _live_in(groups)) and time.monotonic() - t0 < timeout:
        time.sleep(0.05)
    return live


@needs_cc
@pytest.mark.parametrize("how", ["exit", "SIGTERM", "SIGKILL"])
def test_compilers_do_not_outlive_their_process(how, tmp_path):
    proc, report = _child_build(how, tmp_path)
    with proc:  # its pipe closed at the end
        if how != "exit":
            proc.send_signal(getattr(signal, how))
        code = proc.wait(timeout=60)
    assert code == (0 if how == "exit" else -getattr(signal, how))
    assert _gone(report["groups"]) == []


@needs_cc
def test_a_build_past_its_timeout_is_killed(cache, monkeypatch):
    assert native.wait(300)  # kernels built for earlier tests: no child of ours left running
    compiled = _problem("off").compile()
    key = codegen.library_key(compiled.nlp, "timeout test")
    groups: list[int] = []
    spawn = _lifeline.spawn

    def recorded(cmd, log):
        proc = spawn(cmd, log)
        groups.append(proc.pid)
        return proc

    monkeypatch.setattr(_lifeline, "spawn", recorded)
    monkeypatch.setattr(codegen, "COMPILE_TIMEOUT_S", 0.2)
    monkeypatch.setattr(codegen, "_FAILED", set())
    t0 = time.monotonic()
    with pytest.warns(UserWarning, match="longer than 0.2 s"):
        assert codegen.build(key, compiled.sources()) is None
    assert time.monotonic() - t0 < 5.0  # the Hessian alone compiles for seconds
    assert groups and _gone(groups) == [] and _lifeline.running() == []
    assert key in codegen._FAILED and not codegen.library_path(key).exists()
