"""The collision rows' kernels in machine code (posturegen.collision.native): built by a process
of their own, kept on disk, the same numbers as CasADi's virtual machine; a program declared
while they were being built is declared again with them, and solves to the same posture."""

from __future__ import annotations

import copy
import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml

from posturegen import problem_from_dict, solve
from posturegen._cache import clear_caches
from posturegen.cli import _demo_dir
from posturegen.collision import env_slots, native, self_blocks
from posturegen.solver import codegen
from posturegen.solver.compile import MADE, native_kernels

needs_cc = pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")


@pytest.fixture
def kernel_cache(tmp_path, monkeypatch):
    """An empty disk cache, and no kernel in memory, before and after."""
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    clear_caches()
    yield tmp_path
    native.wait()
    clear_caches()


def _small_kernels() -> list[ca.Function]:
    """Self and env kernels of small shapes (3 links, chains of 3 joints)."""
    return self_blocks.kernels(3, 5, 2, 3) + env_slots.kernels(3, 5, 3)


def _random_inputs(fn: ca.Function, rng: np.random.Generator) -> list[ca.DM]:
    """Random arguments for ``fn``."""
    return [ca.DM(rng.uniform(-1, 1, fn.sparsity_in(k).shape)) for k in range(fn.n_in())]


@needs_cc
def test_native_kernels_compute_bit_for_bit_what_the_virtual_machine_does(kernel_cache):
    kernels = _small_kernels()
    assert not native.ready(kernels)  # none on disk: a builder is started
    assert all(native.native(k) is k for k in kernels)  # the virtual machine meanwhile
    assert native.wait(120)
    assert native.ready(kernels) and native.have(kernels)
    rng = np.random.default_rng(11)
    for kernel in kernels:
        compiled = native.native(kernel)
        assert compiled is not kernel
        for _ in range(3):
            args = _random_inputs(kernel, rng)
            for a, b in zip(kernel.call(args), compiled.call(args), strict=True):
                assert np.array_equal(np.array(a), np.array(b)), kernel.name()
    # a later process finds them on disk: loaded, no builder
    clear_caches()
    epoch = native.epoch()
    assert native.ready(kernels) and native.epoch() == epoch
    saved = sorted(p.parent.name.split("-")[0] for p in native.kernel_dir().glob("*/kernel.casadi"))
    assert saved == sorted(k.name() for k in kernels)


def test_without_a_compiler_the_kernels_stay_on_the_virtual_machine(kernel_cache, monkeypatch):
    monkeypatch.setattr(native, "compiler", lambda: None)
    kernels = _small_kernels()
    assert not native.ready(kernels) and not native.have(kernels)
    assert all(native.native(k) is k for k in kernels)
    assert not native._BUILDERS and not native.kernel_dir().exists()


@needs_cc
def test_a_failed_build_is_not_started_again(kernel_cache, monkeypatch):
    monkeypatch.setattr(native, "compiler", lambda: "/bin/false")
    kernels = self_blocks.kernels(3, 5, 2, 3)
    assert not native.ready(kernels)
    assert native.wait(60)
    assert not native.ready(kernels)  # its builder is done, nothing on disk: failed
    assert not native._BUILDERS  # and not sent to another builder
    assert all(native.native(k) is k for k in kernels)


@needs_cc
def test_a_program_declared_while_its_kernels_were_built_is_declared_again_with_them(
    kernel_cache,
):
    """Talos reaching with self-collision avoidance, on the virtual machine (mode cached):
    solved while the kernels are built, then once they are: declared again, the same
    iterations and the same posture bit for bit."""
    data = copy.deepcopy(yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text()))
    data["options"]["self_collision"] = True
    data["tasks"][0]["target"] = [0.3, -0.25, 0.85]
    problem = problem_from_dict(data)
    problem.solver_options = dataclasses.replace(problem.solver_options, codegen="cached")
    assert native_kernels(problem)
    first = solve(problem)
    assert first.success and not first.generated_c
    assert native.wait(120)
    declared = MADE["declared"]
    second = solve(problem)
    assert MADE["declared"] > declared  # declared again: its kernels are now compiled
    assert second.success and second.iterations == first.iterations
    assert np.array_equal(second.x, first.x)
    off = dataclasses.replace(problem.solver_options, codegen="off")
    assert not native_kernels(dataclasses.replace(problem, solver_options=off))


def test_prune_keeps_the_most_recently_used_kernels(tmp_path, monkeypatch):
    """Beyond MAX_CACHE_BYTES the least recently used kernel folders go; a folder without its
    saved function (a build in progress) is not counted nor removed."""
    monkeypatch.setenv("POSTUREGEN_CACHE", str(tmp_path))
    root = native.kernel_dir()
    root.mkdir(parents=True)
    for age, name in enumerate(["new", "mid", "old"]):  # 3 MB each, older and older
        folder = root / name
        folder.mkdir()
        (folder / native.SAVED).write_bytes(b"\0" * (3 << 20))
        os.utime(folder, (1e9 - age * 100, 1e9 - age * 100))
    (root / "building").mkdir()
    monkeypatch.setattr(native, "MAX_CACHE_BYTES", 7 << 20)
    native._prune()
    assert sorted(p.name for p in root.iterdir()) == ["building", "mid", "new"]


def _jobs(folder: Path, kernels: list[ca.Function]) -> Path:
    """A builder's jobs folder holding ``kernels`` (as _build_in_background writes it)."""
    folder.mkdir()
    for k, kernel in enumerate(kernels):
        kernel.save(str(folder / f"{k:02d}-{native.digest_of(kernel)}.casadi"))
    return folder


@needs_cc
def test_two_builders_of_the_same_kernels_compile_each_once(kernel_cache):
    """Two builder processes started together on the same kernels (two workers' builders)
    leave one folder per kernel, every kernel on the disk, and no claim behind."""
    kernels = _small_kernels()
    cc = codegen.compiler()
    env = {**os.environ, "POSTUREGEN_CACHE": str(kernel_cache)}
    jobs = [_jobs(kernel_cache / f"jobs{i}", kernels) for i in range(2)]
    procs = [
        subprocess.Popen([sys.executable, "-m", native.__name__, str(j), cc], env=env) for j in jobs
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    for kernel in kernels:
        digest = native.digest_of(kernel)
        folders = list(native.kernel_dir().glob(f"{kernel.name()}-{digest}-*"))
        assert len(folders) == 1, folders
        assert (folders[0] / native.SAVED).is_file()
    assert not list(native.kernel_dir().glob(".claim-*"))


def test_a_claim_is_held_while_its_builder_lives(kernel_cache):
    """A claim of this host names its process: held while it runs, taken as stale (and
    removed) once it has ended; a second claim of a held digest is refused."""
    native.kernel_dir().mkdir(parents=True)
    claim = native._claim("d1")
    assert claim is not None and native._claim("d1") is None
    assert native._held("d1")
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    host = claim.read_text().split()[0]
    claim.write_text(f"{host} {ended.pid}")
    assert not native._held("d1") and not claim.exists()
    assert native._claim("d1") is not None
