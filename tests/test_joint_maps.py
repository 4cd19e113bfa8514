"""Joint-space maps of the self pairs that spheres cannot hold apart
(posturegen.collision.joint_maps): HRP-2's hips and knee-ankles, whose proxies overlap at the
reference posture while their meshes do not."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from posturegen.collision.active_set import ActiveSet
from posturegen.collision.joint_maps import (
    MAP_FAR,
    JointMap,
    _meet,
    joint_maps,
    mapped_pairs,
    maps_key,
    shipped_maps_dir,
)
from posturegen.collision.proxies import proxy_model
from posturegen.io.problem_file import problem_from_dict
from posturegen.model.robot import BUNDLED, load_bundled
from posturegen.solver.compile import constraint_counts
from posturegen.solver.problem import Program
from tests.stances import talos_on_ground


@pytest.fixture(scope="module")
def hrp2():
    robot = load_bundled("hrp2")
    pm = proxy_model(robot)
    return robot, pm, joint_maps(robot, pm)


def test_the_maps_are_the_pairs_the_spheres_cannot_hold(hrp2):
    robot, pm, maps = hrp2
    names = {tuple(robot.model.names[j] for j in m.joints) for m in maps}
    pairs = ((0, 2), (3, 5))  # hip yaw and pitch; knee and ankle roll
    assert names == {
        (f"{leg}_JOINT{a}", f"{leg}_JOINT{b}") for leg in ("LLEG", "RLEG") for a, b in pairs
    }
    for m in maps:
        assert pm.clearance[pm.link_index(*m.joints)] < 0  # proxies overlap at the reference
        assert len(m.discs) >= 1 and (m.discs[:, 2] > 0).all()
        assert (m.values(pm.rule.reference_q[7:]) > 0).all()  # the reference meets the rows
    talos = load_bundled("talos")
    assert mapped_pairs(talos, proxy_model(talos)) == []


@pytest.mark.parametrize("k", range(4))
def test_where_a_maps_rows_hold_its_meshes_do_not_meet(hrp2, k):
    """Seeded samples of the map's two joints within their limits (the others at the
    reference): every sample that meets the rows has meshes apart; the samples whose meshes
    meet exist (so the check could fail) and each violates a row."""
    robot, pm, maps = hrp2
    m = sorted(maps, key=lambda x: x.joints)[k]
    model, geometry = robot.model, robot.collision_model()
    data, gdata = model.createData(), geometry.createData()
    objs = [
        [i for i, o in enumerate(geometry.geometryObjects) if int(o.parentJoint) == j]
        for j in m.joints
    ]
    iq = [7 + c for c in m.coords]
    lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
    rng = np.random.default_rng(k)
    # half uniform, half near the discs (where the boundary is)
    near = m.discs[rng.integers(len(m.discs), size=300)]
    angle = rng.uniform(0, 2 * np.pi, 300)
    ring = near[:, :2] + (near[:, 2] * rng.uniform(0.9, 1.3, 300))[:, None] * np.column_stack(
        [np.cos(angle), np.sin(angle)]
    )
    samples = np.vstack([rng.uniform(lo, hi, (300, 2)), np.clip(ring, lo, hi)])
    q = pm.rule.reference_q.copy()
    met = 0
    for x in samples:
        q[iq] = x
        pin.forwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, geometry, gdata)
        meet = _meet(geometry, gdata, objs[0], objs[1])
        holds = bool((m.values(q[7:]) >= 0).all())
        assert not (meet and holds), (k, x)
        met += meet
    assert met > 0


def test_the_rows_and_their_derivatives():
    discs = np.array([[0.1, -1.9, 0.2], [0.3, -2.0, 0.15]])
    m = JointMap((2, 4), (1, 3), discs)
    qj = ca.SX.sym("qj", 5)
    f = ca.Function("f", [qj], [m.rows(qj), ca.jacobian(m.rows(qj), qj)])
    rng = np.random.default_rng(0)
    for _ in range(3):
        x = rng.uniform(-2, 2, 5)
        value, jac = (np.array(v) for v in f(x))
        np.testing.assert_allclose(value.ravel(), m.values(x), atol=1e-12)
        fd = np.column_stack(
            [
                (m.values(x + h) - m.values(x - h)) / 2e-6
                for h in np.eye(5) * 1e-6  # central differences
            ]
        )
        np.testing.assert_allclose(jac, fd, atol=1e-6)


def _counts(data: dict) -> dict[str, int]:
    program = Program.of(problem_from_dict(data))
    term = ActiveSet.of(program).term(program.collision_options.margin)
    return constraint_counts(program.but(collision_term=term))


def test_a_hrp2_program_holds_the_rows_and_talos_has_none():
    data = talos_on_ground(self_collision=True)
    assert "collision.self" in _counts(data)
    assert "collision.joint_maps" not in _counts(data)
    data["robot"] = "hrp2"
    robot = load_bundled("hrp2")
    maps = joint_maps(robot, proxy_model(robot))
    assert _counts(data)["collision.joint_maps"] == sum(len(m.discs) for m in maps)


def test_the_bundled_robots_maps_ship_in_the_package():
    """Exactly one file per bundled robot (run tools/ship_proxies.py after a change of
    collision/joint_maps.py or of a robot's proxies)."""
    keys = set()
    for name in BUNDLED:
        robot = load_bundled(name)
        keys.add(maps_key(proxy_model(robot)))
    assert {p.stem for p in shipped_maps_dir().glob("*.npz")} == keys


def _rows(maps: tuple[JointMap, ...], ks: set[int]) -> np.ndarray:
    """(n,) whether each row of the maps' block is one of the maps ``ks``."""
    return np.concatenate([np.full(len(m.discs), k in ks) for k, m in enumerate(maps)])


def test_far_maps_hold_from_the_start_the_others_once_near_a_disc():
    """Standing, the maps whose discs are MAP_FAR from the reference (HRP-2's hips) hold from
    the first scan and the knee-ankles' rows stay unbounded; with a knee-ankle inside a disc
    the scan finds that map violated, and once grown its rows hold too."""
    data = talos_on_ground(self_collision=True)
    data["robot"] = "hrp2"
    program = Program.of(problem_from_dict(data))
    active = ActiveSet.of(program)
    names = program.robot.model.names
    q = program.q_init.copy()
    margin = program.collision_options.margin
    far = {k for k, reach in enumerate(active.map_reach) if np.isinf(reach)}
    assert {names[active.maps[k].joints[0]] for k in far} == {"LLEG_JOINT0", "RLEG_JOINT0"}
    assert all(active.maps[k].gap(q[7:]) >= MAP_FAR for k in far)
    first = active.scan(q, margin, near=True)
    assert first.near_maps == far and not first.violated_maps
    active.grow(first)
    lb, _ = active.term(margin).bounds(program)["collision.joint_maps"]
    np.testing.assert_array_equal(lb == 0, _rows(active.maps, far))
    assert np.isneginf(lb[~_rows(active.maps, far)]).all()
    k = next(k for k in range(len(active.maps)) if k not in far)
    m = active.maps[k]
    q[7 + np.array(m.coords)] = m.discs[0, :2]  # the centre of its first disc
    scan = active.scan(q, margin, near=False)
    assert scan.violated and scan.violated_maps == {k} and m.gap(q[7:]) < 0
    active.grow(scan)
    lb, _ = active.term(margin).bounds(program)["collision.joint_maps"]
    np.testing.assert_array_equal(lb == 0, _rows(active.maps, far | {k}))
