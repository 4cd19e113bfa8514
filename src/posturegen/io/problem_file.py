"""Problem files (YAML, see docs/problem-file.md) -> :class:`~posturegen.solver.problem.Problem`.

Every mistake raises one :class:`~posturegen.errors.InputError` naming the field and the fix.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .. import _fields as F
from .._fields import read_yaml  # the problem file's reader (public here)
from ..collision.boxes import MARGIN, CollisionOptions, excluded_joint_ids
from ..errors import InputError
from ..hints import with_hint
from ..model.robot import Robot, load_robot
from ..model.scene import Scene
from ..plausible import check_angles, check_target
from ..solver import codegen
from ..solver.problem import Problem, SolverOptions, Term
from ..terms.contacts import Contact, ContactEntry, contact_class, contact_types
from ..terms.cop import DEFAULT_COP_MARGIN
from ..terms.costs import ForceCost, PostureCost, TorqueCost
from ..terms.friction import FRICTION_KINDS, FrictionModel
from ..terms.tasks import Task, read_task
from .placement import place_on_fixed_contacts

_TOP_REQUIRED = ("robot", "contacts")
_TOP_OPTIONAL = (
    "mu",
    "surfaces",
    "obstacles",
    "tasks",
    "options",
    "costs",
    "friction",
    "name",
    "description",
)


def load_problem(path: str | Path) -> Problem:
    """Read and validate a problem file.

    Args:
        path: a YAML (or JSON) problem file.

    Returns:
        The Problem (:func:`problem_from_dict` of its content, paths relative to its folder)."""
    path = Path(path)
    return problem_from_dict(read_yaml(path), base_dir=path.parent)


def _friction(value: Any, field: str) -> FrictionModel:
    if value is None:
        return FrictionModel()
    if value == "cone":
        return FrictionModel("cone")
    v = F.require_mapping(value, field)
    F.check_keys(v, field, ["model"], ["faces"])
    kind = F.string(v["model"], f"{field}.model")
    if kind not in FRICTION_KINDS:
        raise InputError(
            f"{field}.model",
            f"unknown friction model '{kind}'",
            with_hint(kind, ("pyramid", "cone"), "use pyramid or cone"),
        )
    faces = F.integer(v.get("faces", 4), f"{field}.faces", 3, "use 4 or 8")
    return FrictionModel(kind, faces)


def _yaw_range(c: dict[str, Any], fld: str) -> tuple[float, float] | None:
    """A floating contact's optional yaw bounds [ψ_min, ψ_max] (rad), less than a turn apart."""
    if c.get("yaw_range") is None:
        return None
    bounds = F.vector(c["yaw_range"], 2, f"{fld}.yaw_range")
    lo, hi = (float(v) for v in bounds)
    if not lo < hi < lo + 2 * np.pi:
        raise InputError(
            f"{fld}.yaw_range",
            f"[{lo:g}, {hi:g}] is not an interval shorter than a turn",
            "write [min, max] in rad with min < max < min + 2π (omit it for any yaw)",
        )
    check_angles(bounds, f"{fld}.yaw_range")
    return lo, hi


def _contact(
    c: Any,
    i: int,
    robot: Robot,
    scene: Scene,
    mu: float,
    friction: FrictionModel,
    names: set[str],
    cop_margin: float = DEFAULT_COP_MARGIN,
) -> Contact:
    fld = f"contacts[{i}]"
    c = F.require_mapping(c, fld)
    types = contact_types()
    any_key = sorted({k for cls in types.values() for k in cls.keys})
    # required first, and misspelt keys of any contact type
    F.check_keys(c, fld, ["robot_patch", "surface", "type"], ["name", *any_key])
    cls = contact_class(F.string(c["type"], f"{fld}.type"), f"{fld}.type")
    F.check_keys(c, fld, ["robot_patch", "surface", "type"], ["name", *cls.keys])
    patch = robot.patch(F.string(c["robot_patch"], f"{fld}.robot_patch"), f"{fld}.robot_patch")
    surface = scene.surface(F.string(c["surface"], f"{fld}.surface"), f"{fld}.surface")
    name = F.string(c.get("name", patch.name), f"{fld}.name")
    if name in names:
        raise InputError(
            f"{fld}.name", f"two contacts are named '{name}'", "give each contact a unique name"
        )
    names.add(name)
    mu_c = F.number(c.get("mu", mu), f"{fld}.mu", minimum=0.0)
    fric = _friction(c["friction"], f"{fld}.friction") if "friction" in c else friction
    yr = _yaw_range(c, fld)
    cop = F.number(c.get("cop_margin", cop_margin), f"{fld}.cop_margin", minimum=0.0)
    grip = F.number(c.get("grip", 0.0), f"{fld}.grip", minimum=0.0)
    return cls.read(c, fld, ContactEntry(name, patch, surface, mu_c, fric, yr, cop, grip))


def _tasks(value: Any, robot: Robot, contacts: list[Any]) -> list[Task]:
    """The tasks of the ``tasks`` list (each by its registered type), their frames and
    joints on the robot; a target out of reach of the contacts is a warning."""
    if not isinstance(value, list):
        raise InputError("tasks", "expected a list", "write tasks: [{type: position, ...}]")
    tasks = [read_task(t, f"tasks[{i}]", i) for i, t in enumerate(value)]
    for i, t in enumerate(tasks):
        t.check_robot(robot, f"tasks[{i}]")
        frame, point = getattr(t, "frame", None), t.target_point()
        if isinstance(frame, str) and point is not None:  # a warning at most
            check_target(robot, frame, point, contacts, f"tasks[{i}].target")
    return tasks


def _costs(value: Any) -> list[Term]:
    v = F.require_mapping(value if value is not None else {}, "costs")
    F.check_keys(v, "costs", [], ["posture", "posture_reference", "forces", "torques"])
    ref = v.get("posture_reference", "initial")
    if ref not in ("initial", "default"):
        raise InputError(
            "costs.posture_reference", f"unknown reference {ref!r}", "use initial or default"
        )
    out: list[Term] = [
        PostureCost(F.number(v.get("posture", 1.0), "costs.posture", minimum=0.0), ref)
    ]
    out.append(ForceCost(F.number(v.get("forces", 1e-2), "costs.forces", minimum=0.0)))
    if v.get("torques"):
        out.append(TorqueCost(F.number(v["torques"], "costs.torques", minimum=0.0)))
    return out


def _solver_options(value: Any) -> SolverOptions:
    v = F.require_mapping(value, "options.solver")
    F.check_keys(
        v,
        "options.solver",
        [],
        [
            "tol",
            "max_iter",
            "max_call_iter",
            "max_cpu_time",
            "print_level",
            "jit",
            "codegen",
            "method",
            "qp",
        ],
    )
    jit = v.get("jit", False)
    if not isinstance(jit, bool):
        raise InputError("options.solver.jit", f"expected true or false, got {jit!r}", "write true")
    mode = v.get("codegen")
    if mode is not None and mode not in codegen.MODES:
        raise InputError(
            "options.solver.codegen",
            f"unknown mode {mode!r}",
            f"use one of: {', '.join(codegen.MODES)}",
        )
    base = SolverOptions()
    call = v.get("max_call_iter")
    return SolverOptions(
        tol=F.number(v.get("tol", base.tol), "options.solver.tol", positive=True),
        max_iter=F.integer(
            v.get("max_iter", base.max_iter), "options.solver.max_iter", 1, "write e.g. 200"
        ),
        max_call_iter=None
        if call is None
        else F.integer(call, "options.solver.max_call_iter", 1, "write e.g. 300"),
        max_cpu_time=F.number(
            v.get("max_cpu_time", base.max_cpu_time), "options.solver.max_cpu_time", positive=True
        ),
        jit=jit,
        codegen=mode,
        method=None if v.get("method") is None else F.string(v["method"], "options.solver.method"),
        qp=None if v.get("qp") is None else F.string(v["qp"], "options.solver.qp"),
        print_level=int(
            F.number(
                v.get("print_level", base.print_level), "options.solver.print_level", minimum=0
            )
        ),
    )


_OPTION_KEYS = (
    "initial",
    "self_collision",
    "solver",
    "torque_limit_scale",
    "environment_collision",
    "collision_margin",
    "collision_exclude",
    "cop_margin",
)


def problem_from_dict(data: Any, base_dir: Path | None = None) -> Problem:
    """Validate a problem-file dict and build the :class:`Problem`.

    Args:
        data: the problem file's content (robot, surfaces, obstacles, contacts, tasks, costs,
            options; lengths in m, angles in rad; see docs/problem-file.md).
        base_dir: the folder that relative paths (a robot's URDF) are relative to.

    Returns:
        The Problem, checked: bad input raises one :class:`~posturegen.errors.InputError`
        naming the field and the fix."""
    data = F.require_mapping(data, "problem")
    F.check_keys(data, "problem", _TOP_REQUIRED, _TOP_OPTIONAL)
    robot = load_robot(data["robot"], base_dir)
    mu = F.number(data.get("mu", 0.7), "mu", minimum=0.0)
    friction = _friction(data.get("friction"), "friction")
    scene = Scene.from_dict(data.get("surfaces", []), data.get("obstacles", []))
    contacts_raw = data["contacts"]
    if not isinstance(contacts_raw, list) or not contacts_raw:
        raise InputError("contacts", "expected a non-empty list", "add at least one contact")
    names: set[str] = set()
    cop = _cop_margin(data.get("options"))
    contacts = [
        _contact(c, i, robot, scene, mu, friction, names, cop) for i, c in enumerate(contacts_raw)
    ]
    tasks = _tasks(data.get("tasks", []) or [], robot, contacts)
    options = F.require_mapping(data.get("options", {}) or {}, "options")
    F.check_keys(options, "options", [], _OPTION_KEYS)
    torque_scale = F.number(
        options.get("torque_limit_scale", 1.0), "options.torque_limit_scale", positive=True
    )
    q_init = robot.initial_configuration(options.get("initial"), "options.initial")
    if not _gives_base(options.get("initial")):  # a name, joints or nothing: place the base
        q_init = place_on_fixed_contacts(robot, q_init, contacts)
    self_collision = _flag(options.get("self_collision", False), "options.self_collision")
    collision = _collision_options(options, robot, scene, self_collision)
    solver = _solver_options(options.get("solver", {}) or {})
    return Problem(
        robot,
        scene,
        contacts,
        tasks,
        _costs(data.get("costs")),
        np.asarray(q_init),
        self_collision,
        torque_scale,
        solver,
        collision,
        cop_margin=cop,
    )


def _collision_options(
    options: Any, robot: Robot, scene: Scene, self_collision: bool
) -> CollisionOptions | None:
    """What to avoid (None: nothing), from the problem's options."""
    env = options.get("environment_collision", "auto")
    if env != "auto":
        env = _flag(env, "options.environment_collision")
    avoid_env = bool(scene.obstacles) if env == "auto" else env
    margin = F.number(
        options.get("collision_margin", MARGIN), "options.collision_margin", minimum=0.0
    )
    exclude = options.get("collision_exclude", []) or []
    if not isinstance(exclude, list) or not all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(n, str) for n in p) for p in exclude
    ):
        raise InputError(
            "options.collision_exclude",
            "expected a list of [link, link] pairs",
            "write [[link_a, link_b], ...]",
        )
    if not (self_collision or avoid_env):
        return None
    collision = CollisionOptions(
        self_collision, margin, tuple(tuple(p) for p in exclude), environment=avoid_env
    )
    excluded_joint_ids(robot, collision)  # names are checked here
    return collision


def _cop_margin(options: Any) -> float:
    """``options.cop_margin`` [m], the default of every force-bearing contact."""
    value = options.get("cop_margin") if isinstance(options, Mapping) else None
    if value is None:
        return DEFAULT_COP_MARGIN
    return F.number(value, "options.cop_margin", minimum=0.0)


def _gives_base(initial: Any) -> bool:
    """Whether ``options.initial`` gives the base placement (the nq numbers of q), rather than
    a reference posture's name, a joint mapping or nothing (the robot's default)."""
    return initial is not None and not isinstance(initial, str | Mapping)


def _flag(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(field, f"expected true or false, got {value!r}", "write true or false")
    return value
