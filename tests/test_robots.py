"""Robot patch files: every patch lies on its link's collision geometry, initial postures stand
on level soles, and each newly shipped robot solves a stand-and-reach problem."""

from __future__ import annotations

import copy

import coal
import numpy as np
import pinocchio as pin
import pytest
import shapely
import yaml

from posturegen import problem_from_dict, solve
from posturegen.cli import _demo_dir
from posturegen.errors import InputError
from posturegen.model.robot import BUNDLED, Patch, Robot, load_robot

ROBOTS = {
    "talos": "talos",
    "g1": "g1",
    "romeo": "romeo",
    "hrp2": "hrp2",
    "atlas": "atlas",
}
PATCHES = ("left_sole", "right_sole", "left_hand", "right_hand")
SUPPORT_TOL = 1e-3  # no geometry beyond the patch plane by more than this [m]
TOUCH_TOL = 2e-3  # vertices this close to the plane touch it [m]
HULL_TOL = 3e-3  # polygon vertices at most this far outside the touching vertices' hull [m]
STAND = yaml.safe_load((_demo_dir() / "stand-reach.yaml").read_text())


def robot_of(name: str) -> Robot:
    return load_robot(ROBOTS[name])


def _sphere_directions(n: int = 400) -> np.ndarray:
    k = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * k / n)
    theta = np.pi * (1 + 5**0.5) * k
    return np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]


def points_in_patch(robot: Robot, patch: Patch) -> np.ndarray:
    """Points (k, 3) of the collision geometry rigidly attached to the patch (every geometry
    of the patch's joint), in the patch frame; a sphere is sampled, its point farthest along
    the patch normal included exactly."""
    T = patch.T_joint_patch
    R, p = np.asarray(T.rotation), np.asarray(T.translation)
    out = []
    for obj in robot.collision_model().geometryObjects:
        if int(obj.parentJoint) != patch.joint_id:
            continue
        g = obj.geometry
        M = obj.placement
        if isinstance(g, coal.BVHModelBase):
            local = np.asarray(g.vertices(), dtype=float)
        elif isinstance(g, coal.Box):
            signs = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
            local = signs * np.asarray(g.halfSide, dtype=float)
        elif isinstance(g, coal.Cylinder):
            n_geom = np.asarray(M.rotation).T @ R[:, 2]
            radial = np.r_[n_geom[:2], 0.0]
            radial = radial / max(np.linalg.norm(radial), 1e-12) * g.radius
            t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
            ring = np.c_[g.radius * np.cos(t), g.radius * np.sin(t), np.zeros(64)]
            ring = np.vstack([ring, radial])  # with the rim point farthest along the normal
            h = np.array([0.0, 0.0, g.halfLength])
            local = np.vstack([ring + h, ring - h])
        elif isinstance(g, coal.Sphere):
            # the patch normal in the geometry's frame, then the sphere sampled around it
            n_geom = np.asarray(M.rotation).T @ R[:, 2]
            local = np.vstack([_sphere_directions(), n_geom]) * g.radius
        else:
            raise AssertionError(f"{obj.name}: no test support for {type(g).__name__}")
        joint_pts = local @ np.asarray(M.rotation).T + np.asarray(M.translation)
        out.append((joint_pts - p) @ R)
    assert out, f"patch {patch.name}: no collision geometry on its joint"
    return np.vstack(out)


def touching_hull(points: np.ndarray) -> shapely.Polygon:
    """Convex hull (patch plane) of the points within TOUCH_TOL of the plane z = 0."""
    touch = points[points[:, 2] >= -TOUCH_TOL]
    assert len(touch) > 0, "no geometry touches the patch plane"
    return shapely.MultiPoint(touch[:, :2]).convex_hull


def worst_outside(hull: shapely.Geometry, vertices: np.ndarray) -> float:
    """Largest distance of a vertex outside ``hull`` (0 inside)."""
    return max(hull.distance(shapely.Point(v)) for v in vertices)


def stand_pose(robot: Robot) -> tuple[pin.Data, float]:
    """FK of the initial posture and the height shift that puts the lowest sole vertex at 0."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.q_init)
    z = [sole_world(robot, data, s)[:, 2].min() for s in ("left_sole", "right_sole")]
    return data, -min(z)


def sole_world(robot: Robot, data: pin.Data, name: str) -> np.ndarray:
    patch = robot.patch(name)
    M = data.oMi[patch.joint_id] * patch.T_joint_patch
    v = patch.polygon.vertices
    local = np.c_[v, np.zeros(len(v))]
    return local @ np.asarray(M.rotation).T + np.asarray(M.translation)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_four_patches_load(name):
    robot = robot_of(name)
    assert set(PATCHES) <= set(robot.patches)
    for p in PATCHES:
        patch = robot.patch(p)
        assert robot.model.existFrame(patch.frame)
        assert patch.polygon.area > 1e-3  # at least 10 cm²


def test_bundled_list():
    assert {"talos", "g1", "romeo"} <= set(BUNDLED)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_patches_lie_on_the_collision_geometry(name):
    robot = robot_of(name)
    for p in PATCHES:
        patch = robot.patch(p)
        pts = points_in_patch(robot, patch)
        beyond = pts[:, 2].max()
        # a supporting plane: nothing beyond it, and it touches the geometry
        assert -SUPPORT_TOL <= beyond <= SUPPORT_TOL, f"{name}.{p}: {beyond * 1e3:.2f} mm"
        hull = touching_hull(pts)
        v = patch.polygon.vertices
        out = worst_outside(hull, v)
        assert out <= HULL_TOL, f"{name}.{p}: a vertex {out * 1e3:.1f} mm off the touching face"
        # the check has teeth: the polygon moved 2 cm in the plane fails it (in at least 7 of
        # 8 directions: a triangle moved towards its sharp apex may still fit), and so does the
        # plane moved 2 cm along its normal (inwards: geometry beyond; outwards: no contact)
        angles = np.radians(np.arange(0, 360, 45))
        shifts = 0.02 * np.c_[np.cos(angles), np.sin(angles)]
        caught = [worst_outside(hull, v + s) > HULL_TOL for s in shifts]
        assert sum(caught) >= 7, f"{name}.{p}: {caught}"
        assert (pts[:, 2] + 0.02).max() > SUPPORT_TOL
        assert not np.any(pts[:, 2] - 0.02 >= -TOUCH_TOL)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_initial_posture_stands_on_level_soles(name):
    robot = robot_of(name)
    data, dz = stand_pose(robot)
    for s in ("left_sole", "right_sole"):
        patch = robot.patch(s)
        M = data.oMi[patch.joint_id] * patch.T_joint_patch
        normal = np.asarray(M.rotation)[:, 2]
        assert normal @ [0, 0, -1] >= np.cos(np.radians(0.5)), f"{name}.{s}: {normal}"
        z = sole_world(robot, data, s)[:, 2] + dz
        assert z.min() >= -1e-12
        assert z.max() <= 5e-3, f"{name}.{s}: sole {z.max() * 1e3:.1f} mm above the ground"


def test_initial_joint_mapping_is_validated():
    robot = robot_of("g1")
    q = robot.initial_configuration({"left_knee_joint": 0.4})
    assert q[robot.model.joints[robot.model.getJointId("left_knee_joint")].idx_q] == 0.4
    # the neutral base orientation, raised so that the lowest sole vertex is at z = 0
    assert np.allclose(q[0:2], 0.0) and np.allclose(q[3:7], [0, 0, 0, 1])
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    lowest = min(sole_world(robot, data, s)[:, 2].min() for s in ("left_sole", "right_sole"))
    assert q[2] > 0.5 and lowest == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(InputError, match="options.initial.left_paw: robot 'g1' has no actuated"):
        robot.initial_configuration({"left_paw": 0.1}, "options.initial")
    with pytest.raises(InputError, match="outside the joint limits"):
        robot.initial_configuration({"left_knee_joint": 3.5})
    with pytest.raises(InputError, match="expected a number"):
        robot.initial_configuration({"left_knee_joint": "bent"})
    with pytest.raises(InputError, match="no actuated joint 'root_joint'"):
        robot.initial_configuration({"root_joint": 0.0})


def stand_reach(name: str, hand_frame: str, offset: list[float]) -> dict:
    """Both soles fixed where the initial posture puts them, a hand frame moved by ``offset``
    from its initial position."""
    robot = robot_of(name)
    data, dz = stand_pose(robot)
    pin.updateFramePlacements(robot.model, data)
    data_dict = copy.deepcopy(STAND)
    data_dict["robot"] = ROBOTS[name]
    for contact in data_dict["contacts"]:
        patch = robot.patch(contact["robot_patch"])
        M = data.oMi[patch.joint_id] * patch.T_joint_patch
        contact["position"] = np.asarray(M.translation)[:2].round(4).tolist()
        contact["yaw"] = float(np.arctan2(M.rotation[1, 0], M.rotation[0, 0]))
    hand = np.asarray(data.oMf[robot.frame_id(hand_frame)].translation) + [0, 0, dz]
    target = (hand + offset).round(3).tolist()
    data_dict["tasks"] = [{"type": "position", "frame": hand_frame, "target": target}]
    data_dict["options"] = {"self_collision": False}
    return data_dict


@pytest.mark.parametrize(
    ("name", "hand_frame", "offset"),
    [
        ("g1", "right_hand_palm_link", [0.08, -0.05, 0.1]),
        ("romeo", "r_gripper", [0.1, -0.05, 0.1]),
        ("atlas", "r_hand_face", [0.1, -0.1, 0.15]),
    ],
)
def test_new_robot_stands_and_reaches(name, hand_frame, offset):
    problem = problem_from_dict(stand_reach(name, hand_frame, offset))
    result = solve(problem)
    assert result.success, result.message
    assert result.verification.ok, result.verification.summary()
    robot = robot_of(name)
    total = sum(f.force for fs in result.forces.values() for f in fs)
    np.testing.assert_allclose(total, [0, 0, robot.weight], atol=1e-6 * robot.weight)


@pytest.mark.parametrize(
    ("name", "height"), [("g1", 0.55), ("romeo", 0.6), ("hrp2", 0.55), ("atlas", 0.75)]
)
def test_hand_patch_rests_on_a_table(name, height):
    """The new hand patches are usable: both feet fixed, the right hand's patch in a support
    (non-inclusive, force-bearing) contact with a table top in front."""
    data = stand_reach(name, robot_of(name).patch("right_hand").frame, [0, 0, 0])
    data["tasks"] = []
    square = [[-0.15, -0.15], [0.15, -0.15], [0.15, 0.15], [-0.15, 0.15]]
    data["surfaces"].append(
        {"name": "table", "position": [0.35, -0.25, height], "rpy": [0, 0, 0], "vertices": square}
    )
    data["contacts"].append({"robot_patch": "right_hand", "surface": "table", "type": "support"})
    result = solve(problem_from_dict(data))
    assert result.success, result.message
    assert result.verification.ok, result.verification.summary()


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_default_posture_stands_on_the_ground(name):
    """Every robot's default posture has its lowest sole vertex at z = 0 (a URDF root at the
    origin would put the feet under the ground, and a solver started there can settle in a
    crouch: HRP-2 ended 0.26 m high instead of 0.65), with both soles level."""
    robot = robot_of(name)
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.q_init)
    z = np.concatenate([sole_world(robot, data, s)[:, 2] for s in ("left_sole", "right_sole")])
    assert z.min() == pytest.approx(0.0, abs=2e-4)  # Talos: its SRDF base height, 1.01927 m
    assert z.max() < 0.01  # the soles are flat on the ground, not only their lowest corner


def test_an_explicit_initial_configuration_is_kept_as_given():
    robot = robot_of("hrp2")
    q = robot.q_init.copy()
    q[0:3] = 0.0  # a user's own base placement, even under the ground, is not moved
    np.testing.assert_array_equal(robot.initial_configuration(q.tolist()), q)
    lifted = robot.initial_configuration("half_sitting")  # a named posture stands on z = 0
    assert lifted[2] == pytest.approx(robot.q_init[2], abs=1e-12) and lifted[2] > 0.6
