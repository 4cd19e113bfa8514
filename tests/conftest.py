"""Shared fixtures: robots (all shipped by name: Talos, G1, Romeo, HRP-2, ATLAS)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import coal
import numpy as np
import pinocchio as pin
import pytest

from posturegen.model.robot import load_bundled, shipped_models_dir

# Solvers run CasADi's virtual machine in the tests (no background compilation of every reused
# structure into ~/.cache); tests/test_codegen.py sets its modes explicitly.
os.environ.setdefault("POSTUREGEN_CODEGEN", "off")

# the URDF files of the paper's robots that posturegen ships (for tests that load them by path)
HRP2_URDF = shipped_models_dir() / "hrp2" / "hrp2.urdf"


@pytest.fixture(scope="session")
def talos():
    return load_bundled("talos")


def first_run_stops_early(real: Callable, calls: list, record: Callable) -> Callable:
    """A stand-in for one of solve()'s steps ``real(program, x0, prior, *rest)`` (a
    :class:`posturegen.solver.problem.Program`) whose first call stops IPOPT after 3
    iterations (a failure); each call appends ``record(program, x0, prior)`` to ``calls``."""

    def step(program: Any, x0: Any, prior: Any, *rest: Any) -> Any:
        calls.append(record(program, x0, prior))
        if len(calls) == 1:
            options = dataclasses.replace(program.solver_options, max_iter=3)
            return real(program.but(solver_options=options), x0, prior, *rest)
        return real(program, x0, prior, *rest)

    return step


def brute_force_intersections(posture: dict[str, Any]) -> list[str]:
    """Every pair of collision objects of two links that intersect (coal) in the posture,
    but those of one joint or of parent and child joints, those the SRDF disables, those of
    links whose meshes overlap at the reference posture (the SRDF's half_sitting, else the
    neutral one) and the user's: computed here from the URDF and SRDF alone."""
    robot = posture["robot"]
    model = pin.buildModelFromUrdf(robot["urdf"], pin.JointModelFreeFlyer())
    geometry = pin.buildGeomFromUrdf(
        model, robot["urdf"], pin.GeometryType.COLLISION, package_dirs=robot["package_dirs"]
    )
    everything = geometry.copy()
    everything.addAllCollisionPairs()
    allowed = {(p.first, p.second) for p in everything.collisionPairs}
    if robot.get("srdf"):
        pin.removeCollisionPairs(model, everything, robot["srdf"], False)
        allowed = {(p.first, p.second) for p in everything.collisionPairs}
    parent = [int(o.parentJoint) for o in geometry.geometryObjects]
    names = model.names
    user = {
        tuple(sorted(e["pair"]))
        for e in posture["collision"].get("unchecked", [])
        if e["reason"] == "user"
    }
    q_ref = pin.neutral(model)
    if robot.get("srdf"):
        probe = pin.Model(model)
        pin.loadReferenceConfigurations(probe, robot["srdf"], False)
        refs = {str(e.key()): np.array(e.data()) for e in probe.referenceConfigurations}
        q_ref = refs.get("half_sitting", q_ref)
    at_reference = colliding_pairs(model, geometry, q_ref, sorted(allowed))
    overlapping = {tuple(sorted((parent[i], parent[j]))) for i, j in at_reference}
    out = []
    for i, j in colliding_pairs(model, geometry, np.asarray(posture["q"]), sorted(allowed)):
        a, b = parent[i], parent[j]
        if a == b or model.parents[a] == b or model.parents[b] == a:
            continue
        if tuple(sorted((a, b))) in overlapping or tuple(sorted((names[a], names[b]))) in user:
            continue
        out.append(f"{geometry.geometryObjects[i].name}/{geometry.geometryObjects[j].name}")
    return out


def hits_in(detail: str, hits: list[str]) -> str:
    """The pair that ``detail`` names first, if it is one of ``hits``."""
    first = detail.split(" ")[0]
    return first if first in hits else "<not a hit>"


def colliding_pairs(model, geometry, q, pairs) -> list[tuple[int, int]]:
    """The geometry pairs (i, j) among ``pairs`` that coal finds colliding at q."""
    data, gdata = model.createData(), geometry.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, geometry, gdata)
    out = []
    for i, j in pairs:
        Mi, Mj = gdata.oMg[i], gdata.oMg[j]
        if coal.collide(
            geometry.geometryObjects[i].geometry,
            coal.Transform3s(Mi.rotation, Mi.translation),
            geometry.geometryObjects[j].geometry,
            coal.Transform3s(Mj.rotation, Mj.translation),
            coal.CollisionRequest(),
            coal.CollisionResult(),
        ):
            out.append((i, j))
    return out
