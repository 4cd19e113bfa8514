#!/usr/bin/env python3
"""Drake peer of ``posturegen bench``: solve posturegen's exported problems with Drake.

Usage: ``drake_peer.py PROBLEMS.jsonl --out RESULTS.jsonl [--solvers ipopt,snopt] [--max N]
[--time-limit S]``; run through ``tools/drake_peer.sh``, which keeps Drake in its own virtual
environment (Drake is no dependency of posturegen; this script needs only drake and numpy).

The problems are written by ``posturegen.bench.peer`` (one JSON object a line). Each is built
as one MathematicalProgram in the decision variables q (the plant's positions: the floating
base's quaternion wxyz and position, then the joints, mapped to posturegen's by name) and λ_i
(one world force f_i = W·λ_i on the robot a contact point, W = m·|g| the robot's weight), from
scratch for every solver (what a planner pays). The MultibodyPlant/SceneGraph of a robot is
built once and reused across problems (with a warm-up: the first problem's program built and
evaluated once, untimed); a problem's boxes go into its own SceneGraph contexts. The program:

- cost: Σ_j (q_j - q_init,j)² over the actuated joints + 1e-6·Σ|λ_i|²;
- q within the URDF's joint limits, |quaternion| = 1;
- fixed contact: p_link(q) = p_target (PositionConstraint) and vee(E - Eᵀ)/2 = 0,
  trace(E) >= 0 with E = R_targetᵀ·R_link(q) (Drake's OrientationConstraint at θ = 0 is
  trace(E) >= 3, an inequality whose gradient vanishes at its only feasible point); with a
  ``cop_margin`` in the contact, the centre of pressure that far inside the polygon of the
  contact's points;
- friction: n·f >= 0 and t_k·f <= μ·cos(π/F)·n·f, t_k = cos(2πk/F)·t1 + sin(2πk/F)·t2 with t1
  the contact's ``tangent_world`` (without it, the world x axis, y if x is nearly along n)
  projected on the contact plane, t2 = n × t1;
- equilibrium: τ_g(q) + Σ_i J_i(q)ᵀ f_i + B·τ = 0 (τ_g: the generalized forces applied by
  gravity), i.e. r = -(τ_g + Σ J_iᵀ f_i) has base rows 0 and actuated rows τ with
  |τ_j| <= s·effort_j (rows scaled by 1/W and 1/effort_j; a Python constraint evaluated over
  AutoDiffXd as one inverse dynamics at v = v̇ = 0 with gravity and the forces applied);
- tasks: p_point(q) = target (PositionConstraint);
- collision: signed distance(link a, link b) >= hold for each listed self pair, one
  MinimumDistanceLowerBoundConstraint per distinct hold, each on a SceneGraph context whose
  collision filter leaves only that group's pairs; distance(link, box) >= margin for every
  link with collision geometry but the box's allowed links. A "link" is the URDF link that
  posturegen names together with every link welded to it (Pinocchio merges fixed joints).
  Drake's proximity engine takes each mesh as its convex hull (posturegen holds the holds on
  sphere proxies of the meshes; the holds are kept as given).

Drake reads no STL: each collision mesh is converted to OBJ (its URDF scale baked in) into a
cache folder; visual, mimic, dynamics, transmission and gazebo elements are dropped.

Output, one JSON line per (problem, solver): family, index, solver, success (Drake's
is_success()), status, solve_s (the Solve() call), total_s (building the program + Solve()),
iterations (IPOPT's, SNOPT's major ones, from the solver's log), cost, max_violation,
verified, checks, q (posturegen's order, as q_init), forces [N] (world, per point), or error.
The checks re-measure every constraint at the returned (q, λ) with the float plant (forces
through translational Jacobians, not the inverse dynamics of the constraint), in posturegen's
units: pose and task errors [m, rad], equilibrium residual / W, torque excess / effort,
friction excess / W, centre-of-pressure shortfall [m], joint-limit excess [rad],
|‖quaternion‖ - 1|, and max over pairs of (hold - distance) [m]; ``verified``: each <= 1e-4.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import statistics
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.geometry import (
    Box,
    CollisionFilterDeclaration,
    GeometryId,
    GeometryInstance,
    GeometrySet,
    ProximityProperties,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    AddUnitQuaternionConstraintOnPlant,
    MinimumDistanceLowerBoundConstraint,
    PositionConstraint,
)
from pydrake.multibody.math import SpatialForce_
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces_
from pydrake.solvers import (
    CommonSolverOption,
    IpoptSolver,
    MathematicalProgram,
    MathematicalProgramResult,
    SnoptSolver,
    SolverOptions,
)
from pydrake.systems.framework import Context, Diagram, DiagramBuilder

TOL_VERIFIED = 1e-4  # every re-measured check must be within this
SOLVER_TOL = 1e-6  # optimality and feasibility tolerances given to IPOPT and SNOPT
FORCE_REG = 1e-6  # weight of Σ|λ|² in the cost
INFLUENCE = 0.01  # [m] MinimumDistanceLowerBoundConstraint's influence distance offset
DRAKE_MESHES = (".obj", ".vtk", ".gltf")
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "posturegen-drake-peer"


# ---------------------------------------------------------------- robot model (built once)


def _read_stl(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and triangles (T, 3) of a binary or ASCII STL file (vertices merged)."""
    data = path.read_bytes()
    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if len(data) == 84 + 50 * count:
        rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
        corners = np.frombuffer(data, rec, count, 84)["v"].reshape(-1, 3).astype(float)
    else:
        nums = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
        corners = np.array(nums, dtype=float).reshape(-1, 3)
    vertices, inverse = np.unique(corners, axis=0, return_inverse=True)
    return vertices, inverse.reshape(-1, 3)


def _obj_of(mesh: Path, scale: np.ndarray) -> Path:
    """An OBJ copy of ``mesh`` with ``scale`` applied (cached by path, size, mtime, scale)."""
    stat = mesh.stat()
    key = f"{mesh.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{scale.tolist()}"
    out = CACHE / "meshes" / f"{hashlib.sha1(key.encode()).hexdigest()[:20]}.obj"
    if out.exists():
        return out
    if mesh.suffix.lower() != ".stl":
        raise ValueError(f"{mesh}: only STL meshes are converted for Drake")
    vertices, triangles = _read_stl(mesh)
    vertices = vertices * scale
    if np.prod(scale) < 0:  # a mirror: keep the triangles' outward winding
        triangles = triangles[:, ::-1]
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=out.parent, delete=False, suffix=".tmp") as tmp:
        tmp.write("\n".join(lines) + "\n")
    os.replace(tmp.name, out)
    return out


def _register_packages(parser: Parser, urdf_text: str, package_dirs: list[str]) -> None:
    """Map each ``package://NAME`` of the URDF to the first ``DIR/NAME`` that exists among the
    problem's package folders (else let Drake crawl those folders for package.xml files)."""
    packages, missing = parser.package_map(), False
    for name in sorted(set(re.findall(r"package://([^/\"']+)/", urdf_text))):
        if packages.Contains(name):
            continue
        found = [Path(d) / name for d in package_dirs if (Path(d) / name).is_dir()]
        if found:
            packages.Add(name, str(found[0]))
        else:
            missing = True
    for d in package_dirs if missing else []:
        if Path(d).is_dir():
            packages.PopulateFromFolder(d)


def _resolve(uri: str, parser: Parser, urdf: Path) -> Path:
    """The file a URDF mesh URI names (package://, file:// or a path relative to the URDF)."""
    if uri.startswith("package://"):
        name, _, rest = uri[len("package://") :].partition("/")
        return Path(parser.package_map().GetPath(name)) / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://") :])
    return (urdf.parent / uri).resolve()


def _drake_urdf(urdf: Path, parser: Parser) -> str:
    """The URDF text for Drake: every collision mesh an OBJ file:// URI with its scale baked
    in; no visual elements, no mimic tags (Pinocchio's parser, hence posturegen, moves each
    joint on its own), no joint dynamics (damping and friction vanish at rest), no
    transmission or gazebo elements."""
    root = ET.parse(urdf).getroot()
    dropped = ("visual", "mimic", "dynamics", "transmission", "gazebo")
    for parent in list(root.iter()):
        for child in [c for c in parent if c.tag in dropped]:
            parent.remove(child)
    for mesh in root.iter("mesh"):
        path = _resolve(mesh.get("filename", ""), parser, urdf)
        scale = np.array([float(s) for s in mesh.get("scale", "1 1 1").split()])
        scale = np.broadcast_to(scale, 3).copy()
        if path.suffix.lower() in DRAKE_MESHES and np.allclose(scale, 1.0):
            mesh.set("filename", path.as_uri())
            continue
        mesh.set("filename", _obj_of(path, scale).as_uri())
        mesh.attrib.pop("scale", None)
    return ET.tostring(root, encoding="unicode")


@dataclass
class Robot:
    """A robot's Drake models, built once: the float plant and its scene graph in a diagram,
    the AutoDiffXd plant, the floating base body, and each link's collision geometries."""

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: SceneGraph
    plant_ad: Any
    base: Any
    build_s: float
    geometries: dict[str, list[GeometryId]] = field(default_factory=dict)

    def link_geometries(self, name: str) -> list[GeometryId]:
        """The collision geometries of link ``name`` and of every link welded to it."""
        if name not in self.geometries:
            body = self.plant.GetBodyByName(name)
            ids: list[GeometryId] = []
            for b in self.plant.GetBodiesWeldedTo(body):
                if b.index() != self.plant.world_body().index():
                    ids += self.plant.GetCollisionGeometriesForBody(b)
            self.geometries[name] = ids
        return self.geometries[name]


_ROBOTS: dict[tuple[str, tuple[str, ...]], Robot] = {}


def robot_of(problem: dict[str, Any]) -> Robot:
    """The problem's robot (cached per URDF and package folders): parse, finalize (the root
    link floats), convert to AutoDiffXd, warm up."""
    key = (problem["urdf"], tuple(problem["package_dirs"]))
    if key in _ROBOTS:
        return _ROBOTS[key]
    t0 = time.perf_counter()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    parser = Parser(plant)
    urdf = Path(problem["urdf"])
    _register_packages(parser, urdf.read_text(), problem["package_dirs"])
    parser.AddModelsFromString(_drake_urdf(urdf, parser), "urdf")
    plant.Finalize()
    diagram = builder.Build()
    bases = list(plant.GetFloatingBaseBodies())
    if len(bases) != 1:
        raise ValueError(f"expected one floating base, found {len(bases)}")
    base = plant.get_body(bases[0])
    robot = Robot(diagram, plant, scene_graph, plant.ToAutoDiffXd(), base, 0.0)
    _ROBOTS[key] = robot
    try:
        warm_up(robot, problem)
    except Exception:  # best effort: the problem's own run reports what is wrong with it
        pass
    robot.build_s = time.perf_counter() - t0
    return robot


def warm_up(robot: Robot, problem: dict[str, Any]) -> None:
    """Build the problem's program once and evaluate each constraint over AutoDiffXd at its
    initial guess: the one-time costs of a process (first contexts, first AutoDiffXd calls)
    go into the robot's build time, not into the first problem's times."""
    program = build_program(robot, problem)
    for binding in program.prog.GetAllConstraints():
        x = program.guess[program.prog.FindDecisionVariableIndices(binding.variables())]
        binding.evaluator().Eval(InitializeAutoDiff(x).reshape(-1))


# ---------------------------------------------------------------- problem data


def drake_q(robot: Robot, problem: dict[str, Any], q_pin: np.ndarray) -> np.ndarray:
    """Pinocchio's q (base xyz, quaternion xyzw, joints in ``problem['joints']`` order) in
    Drake's order (base quaternion wxyz, base xyz, joints at their position_start)."""
    plant = robot.plant
    q = np.zeros(plant.num_positions())
    start = robot.base.floating_positions_start()
    x, y, z, w = q_pin[3:7]
    q[start : start + 7] = [w, x, y, z, *q_pin[0:3]]
    for name, value in zip(problem["joints"], q_pin[7:], strict=True):
        q[plant.GetJointByName(name).position_start()] = value
    return q


def pinocchio_q(robot: Robot, problem: dict[str, Any], q: np.ndarray) -> np.ndarray:
    """The inverse of :func:`drake_q`."""
    start = robot.base.floating_positions_start()
    w, x, y, z, *p = q[start : start + 7]
    rows, _ = actuated_rows(robot, problem)
    return np.concatenate([p, [x, y, z, w], q[rows]])


def actuated_rows(robot: Robot, problem: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Drake's position indices (nj,) and velocity indices (nj,) of ``problem['joints']``."""
    joints = [robot.plant.GetJointByName(name) for name in problem["joints"]]
    return (
        np.array([j.position_start() for j in joints]),
        np.array([j.velocity_start() for j in joints]),
    )


def weight(problem: dict[str, Any]) -> float:
    """W = m·|g| [N]."""
    return float(problem["mass"] * np.linalg.norm(problem["gravity"]))


@dataclass
class Point:
    """A contact's force point: its link, its position in the link (3,), its contact's unit
    normal n (3,) and friction rows A (F, 3), A·f <= 0 (t_k·f - μcos(π/F)·n·f)."""

    body: Any
    p_link: np.ndarray
    normal: np.ndarray
    friction: np.ndarray


def friction_rows(
    normal: np.ndarray, mu: float, faces: int, tangent: np.ndarray | None = None
) -> np.ndarray:
    """Rows A (faces, 3) of the inscribed pyramid A·f <= 0: t_k·f - μcos(π/F)·(n·f), with
    t_k = cos(2πk/F)·t1 + sin(2πk/F)·t2 (t1 the problem's tangent, else the world x, or y,
    projected on the plane)."""
    n = normal / np.linalg.norm(normal)
    axis = np.eye(3)[0] if abs(n[0]) < 0.9 else np.eye(3)[1]
    if tangent is not None:
        axis = np.asarray(tangent, dtype=float)
    t1 = axis - (axis @ n) * n
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    k = 2 * np.pi * np.arange(faces) / faces
    tangents = np.cos(k)[:, None] * t1 + np.sin(k)[:, None] * t2
    return tangents - mu * np.cos(np.pi / faces) * n


def force_points(robot: Robot, problem: dict[str, Any]) -> list[Point]:
    """Every contact's force points, in the order of the problem's contacts and points."""
    points = []
    for c in problem["contacts"]:
        body = robot.plant.GetBodyByName(c["link"])
        n = np.asarray(c["normal_world"], dtype=float)
        rows = friction_rows(n, float(c["mu"]), int(c["friction_faces"]), c.get("tangent_world"))
        for p in c["points_link"]:
            points.append(Point(body, np.asarray(p, dtype=float), n / np.linalg.norm(n), rows))
    return points


def cop_rows(contact: dict[str, Any]) -> np.ndarray:
    """Rows C (E, 3k) with C·λ >= 0 iff the centre of pressure of the contact's k forces is at
    least ``cop_margin`` [m] inside each of the E edges of the polygon of its points:
    Σ_i (n·λ_i)·(depth_e(p_i) - m) >= 0, depth_e the inward distance from edge e in the plane.
    No rows when the problem gives no ``cop_margin``."""
    margin = float(contact.get("cop_margin") or 0.0)
    points = np.asarray(contact["points_link"], dtype=float)
    if margin <= 0 or len(points) < 3:
        return np.zeros((0, 3 * len(points)))
    n_world = np.asarray(contact["normal_world"], dtype=float)
    n_world = n_world / np.linalg.norm(n_world)
    n_link = pose(contact["T_world_link"]).rotation().inverse().multiply(n_world)
    centre = points.mean(axis=0)
    rel = points - centre
    e1 = rel[0] - (rel[0] @ n_link) * n_link
    e1 /= np.linalg.norm(e1)
    ring = points[np.argsort(np.arctan2(rel @ np.cross(n_link, e1), rel @ e1))]
    rows = []
    for a, b in zip(ring, np.roll(ring, -1, axis=0), strict=True):
        u = np.cross(n_link, b - a)
        u *= np.sign(u @ (centre - a)) / np.linalg.norm(u)
        rows.append(np.kron((points - a) @ u - margin, n_world))
    return np.array(rows)


def pose(matrix: list[list[float]]) -> RigidTransform:
    """A 4×4 homogeneous matrix as a RigidTransform (its rotation re-orthonormalized)."""
    T = np.asarray(matrix, dtype=float)
    u, _, vt = np.linalg.svd(T[:3, :3])
    return RigidTransform(RotationMatrix(u @ vt), T[:3, 3])


# ---------------------------------------------------------------- collision groups


@dataclass
class Group:
    """Geometry pairs held at least ``bound`` apart, on a diagram context whose collision
    filter leaves only those pairs; ``pairs`` names them (link a, link b or box)."""

    bound: float
    context: Context
    pairs: list[tuple[str, str, list[GeometryId], list[GeometryId]]]


def _register_box(robot: Robot, sg_context: Context, box: dict[str, Any]) -> GeometryId:
    """Register ``box`` as an anchored proximity box in one SceneGraph context."""
    sg, source = robot.scene_graph, robot.plant.get_source_id()
    size = 2 * np.asarray(box["half"], dtype=float)
    instance = GeometryInstance(pose(box["T_world_box"]), Box(*size), f"box:{box['name']}")
    gid = sg.RegisterGeometry(sg_context, source, sg.world_frame_id(), instance)
    sg.AssignRole(sg_context, source, gid, ProximityProperties())
    return gid


def _only_pairs(robot: Robot, sg_context: Context, group: Group) -> None:
    """Filter every pair of the context's proximity geometries but the group's."""
    inspector = robot.scene_graph.get_query_output_port().Eval(sg_context).inspector()
    manager = robot.scene_graph.collision_filter_manager(sg_context)
    everything = GeometrySet(inspector.GetAllGeometryIds(Role.kProximity))
    manager.Apply(CollisionFilterDeclaration().ExcludeWithin(everything))
    for _, _, a, b in group.pairs:
        manager.Apply(CollisionFilterDeclaration().AllowBetween(GeometrySet(a), GeometrySet(b)))


def collision_groups(robot: Robot, problem: dict[str, Any]) -> list[Group]:
    """One group per distinct hold of the self pairs, and one for the boxes (at the margin)."""
    holds: dict[float, list[tuple[str, str, list[GeometryId], list[GeometryId]]]] = {}
    for pair in problem["self_pairs"]:
        a, b = pair["links"]
        ga, gb = robot.link_geometries(a), robot.link_geometries(b)
        if ga and gb:
            holds.setdefault(float(pair["hold"]), []).append((a, b, ga, gb))
    groups = []
    for bound, pairs in sorted(holds.items()):
        groups.append(Group(bound, robot.diagram.CreateDefaultContext(), pairs))
    if problem["boxes"]:
        context = robot.diagram.CreateDefaultContext()
        sg_context = robot.scene_graph.GetMyMutableContextFromRoot(context)
        inspector = robot.scene_graph.model_inspector()
        robot_ids = inspector.GetAllGeometryIds(Role.kProximity)
        pairs = []
        for box in problem["boxes"]:
            gid = _register_box(robot, sg_context, box)
            allowed = {g for name in box["allowed_links"] for g in robot.link_geometries(name)}
            free = [g for g in robot_ids if g not in allowed]
            pairs.append(("robot", f"box:{box['name']}", free, [gid]))
        groups.append(Group(float(problem["margin"]), context, pairs))
    for group in groups:
        _only_pairs(robot, robot.scene_graph.GetMyMutableContextFromRoot(group.context), group)
    return groups


def pair_distances(robot: Robot, group: Group, q: np.ndarray) -> list[tuple[str, str, float]]:
    """(a, b, signed distance [m]) of each of the group's pairs at q, from Drake's closest
    points (pairs farther than bound + 1 m are reported at that)."""
    plant_context = robot.plant.GetMyMutableContextFromRoot(group.context)
    robot.plant.SetPositions(plant_context, q)
    query = robot.scene_graph.get_query_output_port().Eval(
        robot.scene_graph.GetMyContextFromRoot(group.context)
    )
    found: dict[frozenset[GeometryId], float] = {}
    for d in query.ComputeSignedDistancePairwiseClosestPoints(group.bound + 1.0):
        found[frozenset((d.id_A, d.id_B))] = d.distance
    out = []
    for a, b, ga, gb in group.pairs:
        ds = [found.get(frozenset((x, y)), group.bound + 1.0) for x in ga for y in gb]
        out.append((a, b, min(ds)))
    return out


# ---------------------------------------------------------------- the program


@dataclass
class Program:
    """One problem's MathematicalProgram, its variables q (nq,) and λ (k, 3), its initial
    guess (in the program's variable order), and what its constraints need kept alive."""

    prog: MathematicalProgram
    q: np.ndarray
    lam: np.ndarray
    guess: np.ndarray
    points: list[Point]
    groups: list[Group]
    keep: list[Any] = field(default_factory=list)


class Evaluator:
    """The float or AutoDiffXd plant and a context of it, picked by the argument's type (Drake
    calls a Python constraint with float values, or with AutoDiffXd to get gradients)."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.contexts = (robot.plant.CreateDefaultContext(), robot.plant_ad.CreateDefaultContext())

    def at(self, q: np.ndarray) -> tuple[Any, Context, type]:
        """(plant, context, scalar type) with the context's positions set to q."""
        if q.dtype == object:
            plant, context, scalar = self.robot.plant_ad, self.contexts[1], AutoDiffXd
        else:
            plant, context, scalar = self.robot.plant, self.contexts[0], float
        plant.SetPositions(context, q)
        return plant, context, scalar


def _add_configuration(robot: Robot, problem: dict[str, Any], program: Program) -> None:
    """Joint limits, |quaternion| = 1, and the cost Σ_j (q_j - q_init,j)² + ε·Σ|λ|²."""
    plant, prog, q = robot.plant, program.prog, program.q
    prog.AddBoundingBoxConstraint(plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits(), q)
    AddUnitQuaternionConstraintOnPlant(plant, q, prog)
    rows, _ = actuated_rows(robot, problem)
    q0 = prog.GetInitialGuess(q)
    prog.AddQuadraticErrorCost(np.eye(len(rows)), q0[rows], q[rows])
    lam = program.lam.reshape(-1)
    prog.AddQuadraticErrorCost(FORCE_REG * np.eye(len(lam)), np.zeros(len(lam)), lam)


def _orientation_rows(evaluator: Evaluator, body: Any, R_target: np.ndarray) -> Any:
    """The constraint function q ↦ (vee(E - Eᵀ)/2, trace E), E = R_targetᵀ·R_link(q)."""
    index = body.index()

    def rows(q: np.ndarray) -> np.ndarray:
        """(vee(E - Eᵀ)/2 (3,), trace E) at q, float or AutoDiffXd."""
        plant, context, _ = evaluator.at(q)
        R = plant.get_body(index).EvalPoseInWorld(context).rotation().matrix()
        E = R_target.T @ R
        vee = [E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]]
        return np.array([0.5 * v for v in vee] + [E[0, 0] + E[1, 1] + E[2, 2]])

    return rows


def _add_contacts(robot: Robot, problem: dict[str, Any], program: Program) -> None:
    """Each contact's link at its pose (position and orientation), its centre of pressure
    inside (when the problem gives a ``cop_margin``), each force in its friction pyramid
    (n·λ >= 0, A·λ <= 0)."""
    plant, prog = robot.plant, program.prog
    context = plant.CreateDefaultContext()
    evaluator, start = Evaluator(robot), 0
    program.keep += [context, evaluator]
    for c in problem["contacts"]:
        body = plant.GetBodyByName(c["link"])
        X = pose(c["T_world_link"])
        p = X.translation()
        position = PositionConstraint(
            plant, plant.world_frame(), p, p, body.body_frame(), np.zeros(3), context
        )
        prog.AddConstraint(position, program.q).evaluator().set_description(f"{c['name']}.pos")
        rows = _orientation_rows(evaluator, body, X.rotation().matrix())
        lb, ub = np.array([0, 0, 0, 0.0]), np.array([0, 0, 0, np.inf])
        prog.AddConstraint(rows, lb, ub, program.q, f"{c['name']}.rot")
        k = len(c["points_link"])
        C, lam = cop_rows(c), program.lam[start : start + k].reshape(-1)
        if len(C):
            prog.AddLinearConstraint(C, np.zeros(len(C)), np.full(len(C), np.inf), lam)
        start += k
    for point, lam in zip(program.points, program.lam, strict=True):
        prog.AddLinearConstraint(point.normal[None, :], [0.0], [np.inf], lam)
        F = len(point.friction)
        prog.AddLinearConstraint(point.friction, np.full(F, -np.inf), np.zeros(F), lam)


def _equilibrium_rows(robot: Robot, problem: dict[str, Any], points: list[Point]) -> Any:
    """The function x = (q, λ) ↦ r = -(τ_g(q) + Σ J_iᵀ W·λ_i) (nv,): one inverse dynamics at
    v = v̇ = 0 with the plant's force elements (gravity) and the contact forces applied; base
    rows / W, actuated rows / effort_j."""
    evaluator, W = Evaluator(robot), weight(problem)
    nq, nv = robot.plant.num_positions(), robot.plant.num_velocities()
    base = robot.base.floating_velocities_start_in_v() + np.arange(6)
    _, act = actuated_rows(robot, problem)
    effort = np.asarray(problem["effort"], dtype=float)
    scale = np.where(np.isfinite(effort) & (effort > 0), effort, 1.0)
    zeros = {float: np.zeros(nv), AutoDiffXd: np.array([AutoDiffXd(0.0)] * nv)}

    def rows(x: np.ndarray) -> np.ndarray:
        """(r[base] / W, r[actuated] / effort) at x = (q, λ), float or AutoDiffXd."""
        plant, context, T = evaluator.at(x[:nq])
        forces = MultibodyForces_[T](plant)
        plant.CalcForceElementsContribution(context, forces)
        for point, lam in zip(points, x[nq:].reshape(-1, 3), strict=True):
            body = plant.get_body(point.body.index())
            p_W = body.EvalPoseInWorld(context).rotation().matrix() @ point.p_link
            force = SpatialForce_[T](zeros[T][:3], W * lam)
            body.AddInForce(context, p_W, force, plant.world_frame(), forces)
        r = plant.CalcInverseDynamics(context, zeros[T], forces)
        return np.concatenate([r[base] / W, r[act] / scale])

    return rows


def _add_equilibrium(robot: Robot, problem: dict[str, Any], program: Program) -> None:
    """Static equilibrium: base rows of r zero, actuated rows |τ_j| <= s·effort_j."""
    rows = _equilibrium_rows(robot, problem, program.points)
    effort = np.asarray(problem["effort"], dtype=float)
    limited = np.isfinite(effort) & (effort > 0)
    bound = np.where(limited, float(problem["torque_limit_scale"]), np.inf)
    lb, ub = np.concatenate([np.zeros(6), -bound]), np.concatenate([np.zeros(6), bound])
    x = np.concatenate([program.q, program.lam.reshape(-1)])
    program.prog.AddConstraint(rows, lb, ub, x, "equilibrium")
    program.keep.append(rows)


def _add_tasks_and_collision(robot: Robot, problem: dict[str, Any], program: Program) -> None:
    """Each task's point at its target; each collision group's distances above its bound."""
    plant, prog = robot.plant, program.prog
    context = plant.CreateDefaultContext()
    program.keep.append(context)
    for k, task in enumerate(problem["tasks"]):
        frame = plant.GetBodyByName(task["link"]).body_frame()
        target = np.asarray(task["target_world"], dtype=float)
        point = np.asarray(task["point_link"], dtype=float)
        c = PositionConstraint(plant, plant.world_frame(), target, target, frame, point, context)
        prog.AddConstraint(c, program.q).evaluator().set_description(f"task{k}")
    for group in program.groups:
        plant_context = plant.GetMyMutableContextFromRoot(group.context)
        c = MinimumDistanceLowerBoundConstraint(plant, group.bound, plant_context, None, INFLUENCE)
        prog.AddConstraint(c, program.q).evaluator().set_description(f"distance>={group.bound}")


def build_program(robot: Robot, problem: dict[str, Any]) -> Program:
    """The problem's MathematicalProgram with its initial guess: q_init in Drake's order,
    and the weight shared evenly among the force points along their normals."""
    prog = MathematicalProgram()
    q = prog.NewContinuousVariables(robot.plant.num_positions(), "q")
    points = force_points(robot, problem)
    lam = prog.NewContinuousVariables(len(points), 3, "lambda")
    prog.SetInitialGuess(q, drake_q(robot, problem, np.asarray(problem["q_init"], dtype=float)))
    prog.SetInitialGuess(lam, np.array([p.normal / len(points) for p in points]).reshape(-1, 3))
    guess = prog.GetInitialGuess(prog.decision_variables())
    program = Program(prog, q, lam, guess, points, collision_groups(robot, problem))
    _add_configuration(robot, problem, program)
    _add_contacts(robot, problem, program)
    _add_equilibrium(robot, problem, program)
    _add_tasks_and_collision(robot, problem, program)
    return program


# ---------------------------------------------------------------- checks (float plant)


def _pose_checks(robot: Robot, problem: dict[str, Any], context: Context) -> dict[str, float]:
    """Worst contact position [m] and orientation [rad] error, worst task error [m]."""
    plant, world = robot.plant, robot.plant.world_frame()
    pos, rot, task = 0.0, 0.0, 0.0
    for c in problem["contacts"]:
        frame = plant.GetBodyByName(c["link"]).body_frame()
        X = plant.CalcRelativeTransform(context, world, frame)
        target = pose(c["T_world_link"])
        pos = max(pos, float(np.linalg.norm(X.translation() - target.translation())))
        E = target.rotation().inverse() @ X.rotation()
        rot = max(rot, float(E.ToAngleAxis().angle()))
    for t in problem["tasks"]:
        frame = plant.GetBodyByName(t["link"]).body_frame()
        p = plant.CalcPointsPositions(context, frame, np.asarray(t["point_link"]), world)
        task = max(task, float(np.linalg.norm(p.ravel() - np.asarray(t["target_world"]))))
    return {"contact position": pos, "contact orientation": rot, "task": task}


def _force_checks(
    robot: Robot, problem: dict[str, Any], context: Context, points: list[Point], lam: np.ndarray
) -> dict[str, float]:
    """Equilibrium residual of the base rows / W, torque excess / effort (τ from
    τ_g + Σ J_iᵀ f_i + B·τ = 0, J_i from Drake's translational Jacobians), friction excess / W."""
    plant, world, W = robot.plant, robot.plant.world_frame(), weight(problem)
    total = plant.CalcGravityGeneralizedForces(context)
    friction = 0.0
    for point, lam_i in zip(points, lam, strict=True):
        J = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, point.body.body_frame(), point.p_link, world, world
        )
        total = total + J.T @ (W * lam_i)
        worst = max(-(point.normal @ lam_i), float(np.max(point.friction @ lam_i)))
        friction = max(friction, worst)
    base = robot.base.floating_velocities_start_in_v() + np.arange(6)
    _, act = actuated_rows(robot, problem)
    tau = -total[act]
    effort = np.asarray(problem["effort"], dtype=float)
    limited = np.isfinite(effort) & (effort > 0)
    limit = float(problem["torque_limit_scale"]) * effort
    over = np.where(limited, (np.abs(tau) - limit) / np.where(limited, effort, 1.0), 0.0)
    return {
        "equilibrium": float(np.max(np.abs(total[base]))) / W,
        "torque limits": max(float(np.max(over, initial=0.0)), 0.0),
        "friction": max(friction, 0.0),
    }


def _cop_check(problem: dict[str, Any], lam: np.ndarray) -> dict[str, float]:
    """How far [m] the worst contact's centre of pressure is short of its ``cop_margin``
    inside its polygon (no check when no contact has one)."""
    worst, start, found = 0.0, 0, False
    for c in problem["contacts"]:
        k = len(c["points_link"])
        C, lam_c = cop_rows(c), lam[start : start + k]
        start += k
        normal = float(np.sum(lam_c @ np.asarray(c["normal_world"], dtype=float)))
        if len(C) and normal > 1e-9:
            found = True
            worst = max(worst, -float(np.min(C @ lam_c.reshape(-1))) / normal)
    return {"centre of pressure": worst} if found else {}


def _configuration_checks(robot: Robot, q: np.ndarray) -> dict[str, float]:
    """Joint-limit excess and |‖quaternion‖ - 1|."""
    plant = robot.plant
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    excess = np.maximum(lower - q, q - upper)
    start = robot.base.floating_positions_start()
    return {
        "joint limits": max(float(np.max(excess)), 0.0),
        "quaternion": abs(float(np.linalg.norm(q[start : start + 4])) - 1.0),
    }


def checks(robot: Robot, problem: dict[str, Any], program: Program, x: np.ndarray) -> dict:
    """Every constraint re-measured at the solution x (the program's variable vector), the
    collision check as max over pairs of (hold - signed distance) [m] (0 when all are held)."""
    q = _values(program, program.q, x)
    lam = _values(program, program.lam, x)
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, q)
    out = _pose_checks(robot, problem, context)
    out.update(_force_checks(robot, problem, context, program.points, lam))
    out.update(_cop_check(problem, lam))
    out.update(_configuration_checks(robot, q))
    short = 0.0
    for group in program.groups:
        for _, _, d in pair_distances(robot, group, q):
            short = max(short, group.bound - d)
    out["collision"] = short
    return out


def _values(program: Program, variables: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The values in x (the program's variable vector) of an array of its variables."""
    index = program.prog.FindDecisionVariableIndices(variables.reshape(-1))
    return np.asarray(x)[index].reshape(variables.shape)


# ---------------------------------------------------------------- solving and the run


SOLVERS = {"ipopt": IpoptSolver, "snopt": SnoptSolver}


def solver_options(name: str, time_limit: float, log: Path) -> SolverOptions:
    """Tolerances SOLVER_TOL, the time limit, and the solver's log into ``log``."""
    options = SolverOptions()
    options.SetOption(CommonSolverOption.kPrintFileName, str(log))
    sid = SOLVERS[name]().solver_id()
    if name == "ipopt":
        for key, value in [("tol", SOLVER_TOL), ("constr_viol_tol", SOLVER_TOL)]:
            options.SetOption(sid, key, value)
        options.SetOption(sid, "max_wall_time", float(time_limit))
        options.SetOption(sid, "print_level", 0)
    else:
        for key in ["Major optimality tolerance", "Major feasibility tolerance"]:
            options.SetOption(sid, key, SOLVER_TOL)
        options.SetOption(sid, "Time limit", float(time_limit))
        options.SetOption(sid, "Timing level", 3)  # SNOPT checks no time limit without it
    return options


def iterations(name: str, log: Path) -> int | None:
    """The iteration count in the solver's log (IPOPT: iterations; SNOPT: major iterations)."""
    if not log.exists():
        return None
    text = log.read_text(errors="replace")
    ipopt, snopt = r"Number of Iterations\.+:\s*(\d+)", r"No\. of major iter\w*\s+(\d+)"
    found = re.findall(ipopt if name == "ipopt" else snopt, text)
    return int(found[-1]) if found else None


def run_one(problem: dict[str, Any], name: str, time_limit: float) -> dict[str, Any]:
    """Build the problem's program, solve it with solver ``name``, re-measure the solution."""
    record: dict[str, Any] = {
        "family": problem["family"],
        "index": problem["index"],
        "solver": name,
    }
    solver = SOLVERS[name]()
    if not (solver.available() and solver.enabled()):
        return record | {"success": False, "verified": False, "error": f"{name} unavailable"}
    robot = robot_of(problem)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "solver.log"
        t0 = time.perf_counter()
        program = build_program(robot, problem)
        options = solver_options(name, time_limit, log)
        t1 = time.perf_counter()
        result: MathematicalProgramResult = solver.Solve(program.prog, program.guess, options)
        t2 = time.perf_counter()
        its = iterations(name, log)
    x = result.GetSolution(program.prog.decision_variables())
    measured = checks(robot, problem, program, x)
    q_pin = pinocchio_q(robot, problem, _values(program, program.q, x))
    forces = weight(problem) * _values(program, program.lam, x)
    worst = max(measured.values())
    record |= {
        "success": bool(result.is_success()),
        "status": result.get_solution_result().name,
        "solve_s": t2 - t1,
        "total_s": t2 - t0,
        "iterations": its,
        "cost": float(result.get_optimal_cost()),
        "max_violation": worst,
        "verified": bool(worst <= TOL_VERIFIED),
        "checks": measured,
        "q": q_pin.tolist(),  # Pinocchio's order, as q_init
        "forces": forces.tolist(),  # [N] world, per force point in the contacts' order
    }
    return record


def failed(problem: dict[str, Any], name: str, error: BaseException) -> dict[str, Any]:
    """The record of a run that raised ``error``."""
    return {
        "family": problem.get("family", ""),
        "index": problem.get("index", -1),
        "solver": name,
        "success": False,
        "verified": False,
        "error": f"{type(error).__name__}: {error}",
    }


def summary(records: list[dict[str, Any]]) -> str:
    """Per family and solver: runs, successes, verified, median and p90 of solve_s (over the
    runs that reached the solver)."""
    rows = [
        f"{'family':34} {'solver':6} {'n':>4} {'success':>7} {'verified':>8} "
        f"{'median_s':>9} {'p90_s':>8}"
    ]
    keys = sorted({(r["family"], r["solver"]) for r in records})
    for family, solver in keys:
        runs = [r for r in records if (r["family"], r["solver"]) == (family, solver)]
        times = [r["solve_s"] for r in runs if "solve_s" in r]
        med = f"{statistics.median(times):9.3f}" if times else f"{'-':>9}"
        p90 = f"{float(np.percentile(times, 90)):8.3f}" if times else f"{'-':>8}"
        ok = sum(r["success"] for r in runs)
        good = sum(r["verified"] for r in runs)
        rows.append(f"{family:34} {solver:6} {len(runs):4d} {ok:7d} {good:8d} {med} {p90}")
    return "\n".join(rows)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line (see the module doc)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("problems", type=Path, help="problems written by posturegen (JSONL)")
    parser.add_argument("--out", type=Path, required=True, help="results (JSONL)")
    parser.add_argument("--solvers", default="ipopt,snopt", help="comma-separated: ipopt,snopt")
    parser.add_argument("--max", type=int, default=None, help="solve at most N problems")
    parser.add_argument("--time-limit", type=float, default=60.0, help="[s] per solve")
    args = parser.parse_args(argv)
    args.solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    unknown = [s for s in args.solvers if s not in SOLVERS]
    if unknown:
        parser.error(f"unknown solver(s) {unknown}: use {', '.join(SOLVERS)}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Solve every problem with every solver, one JSON line each into --out, then print the
    summary."""
    args = parse_args(argv)
    lines = [line for line in args.problems.read_text().splitlines() if line.strip()]
    problems = [json.loads(line) for line in lines[: args.max]]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    records = []
    with args.out.open("w") as out:
        for problem in problems:
            for name in args.solvers:
                try:
                    record = run_one(problem, name, args.time_limit)
                except Exception as error:  # a failed run is a result too
                    record = failed(problem, name, error)
                records.append(record)
                out.write(json.dumps(record) + "\n")
                out.flush()
                mark = "ok" if record.get("verified") else record.get("error", "not verified")
                mark = mark[:160]
                print(
                    f"{record['family']}[{record['index']}] {name}: "
                    f"{record.get('solve_s', float('nan')):.3f} s {mark}",
                    file=sys.stderr,
                )
    for robot in _ROBOTS.values():
        print(f"robot model built once in {robot.build_s:.2f} s (not in total_s)")
    print(summary(records))
    return 0


if __name__ == "__main__":
    sys.exit(main())
