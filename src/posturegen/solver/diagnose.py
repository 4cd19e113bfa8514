"""Why no posture was found: the rows an elastic solve had to move, in physical units.

``diagnose(problem, solve(problem))``: when IPOPT did not converge, a copy of the problem whose
tasks, torque limits, contact rows and friction cones are relaxed by L1-penalized slacks
(:mod:`posturegen.terms.elastic`; the static equilibrium stays hard) is solved without collision
avoidance; when no row had to move there and the problem avoids collisions, a copy with only
its collision rows relaxed is solved from that posture. :func:`from_relaxed` turns the
positive slacks into causes, each one sentence with its amount: ``target of task 0 is 0.37 m
beyond reach of gripper_right_base_link``, ``torque limit of leg_left_4_joint exceeded by
35 %``. When IPOPT converged but the re-check rejected its posture, :func:`from_rejection`
names the failed checks. The problem itself is not written on.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from ..collision.active_set import box_label
from ..model.kinematics import scratch_data
from ..terms.elastic import Elastic, slack_values
from ..terms.equilibrium import TORQUE_LIMITS
from ..terms.tasks import Task
from .problem import Program
from .runs import _IPOPT_OK, run_nlp
from .solve import (
    Result,
    _outputs,
    _result,
    _solve_avoiding,
    configuration_from_x,
    solve,
)

# slacks below these are the L1 penalty's noise, not causes
TOL_LENGTH = 1e-3  # [m]
TOL_SINE = 5e-3  # sine of an angle (about 0.3°)
TOL_TORQUE = 5e-3  # fraction of a torque limit
TOL_FORCE = 1e-3  # fraction of the robot's weight
MAX_CAUSES = 3  # causes in the one-line summary (the posture file lists them all)
# the summary names the main causes: those that cost at least this share of the largest one
# (a contact held away from its surface still bears forces, and the feet's friction that
# balances them is a consequence, not a cause)
MAIN_SHARE = 0.1
# a target this far from the robot's initial base [m] whose value in mm is within reach
# is most likely typed in millimetres
MILLIMETRE_DISTANCE = 20.0


@dataclass(frozen=True)
class Cause:
    """One row block that had to move: what, by how much (``amount`` in ``unit``), and the
    sentence; ``penalty`` is what the relaxed program paid for it (the order of causes)."""

    kind: str  # task | torque | contact | friction | collision | check
    subject: str  # the task, joint, contact or pair
    amount: float
    unit: str
    text: str
    penalty: float = 0.0


@dataclass(frozen=True)
class Diagnosis:
    """What blocks a problem: ``line`` (one line), its causes, how the relaxed solve ended."""

    line: str
    causes: tuple[Cause, ...] = ()
    relaxed_status: str | None = None  # IPOPT's status on the elastic program (None: not run)
    feasible: bool = False  # the relaxed program met every row: no constraint blocks it

    def to_dict(self) -> dict[str, Any]:
        """The posture file's ``diagnosis``."""
        return {
            "summary": self.line,
            "feasible": self.feasible,
            "relaxed_status": self.relaxed_status,
            "causes": [
                {
                    "kind": c.kind,
                    "subject": c.subject,
                    "amount": c.amount,
                    "unit": c.unit,
                    "message": c.text,
                    "penalty": c.penalty,
                }
                for c in self.causes
            ],
        }


@dataclass
class Relaxed:
    """The last IPOPT run of an elastic solve (its x, the blocks ``x_index``), its outputs
    and q (nq,); ``problem`` is what the run solved: the relaxed problem (its ``elastic``
    weights) with its last collision rows."""

    problem: Program
    run: Any  # posturegen.solver.solve._Run
    outputs: dict[str, np.ndarray]
    q: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """The solution's variables."""
        return self.run.x

    @property
    def x_index(self) -> dict[str, slice]:
        """The variable blocks of x."""
        return self.run.compiled.x_index

    @property
    def status(self) -> str:
        """IPOPT's status."""
        return str(self.run.status)

    @property
    def converged(self) -> bool:
        """IPOPT converged on the elastic program."""
        return self.run.status in _IPOPT_OK

    def verified(self) -> bool:
        """The relaxed solution passes the re-check of the real problem's posture."""
        return _result(self.problem, [self.run]).verification.ok

    @property
    def slacks(self) -> dict[str, np.ndarray]:
        """The net slack s⁺ - s⁻ of every relaxed block."""
        return slack_values(self.x, self.x_index)

    @property
    def elastic(self) -> Elastic:
        """The relaxation's weights."""
        return self.problem.elastic


# the second stage: only the collision rows relaxed
COLLISION_ONLY = Elastic(weights=(("collision", 100.0),))
# IPOPT iterations of an elastic solve at least (a problem's max_iter limits its own solve)
ELASTIC_MAX_ITER = 300


def diagnose(problem: Any, result: Result) -> Result:
    """``result`` (a failed solve of ``problem``, a :class:`posturegen.solver.problem.Problem`) with
    its diagnosis: ``Result.diagnosis`` (one line) and the posture file's ``diagnosis``
    (:meth:`Diagnosis.to_dict`); a success is returned as it is.

    Args:
        problem: the problem that ``result`` failed.
        result: the failed Result (a success is returned unchanged).

    Returns:
        The Result with ``diagnosis``: the causes that block it, each with its amount [m, deg,
        N·m] (one or two more solves, of an elastic copy of the problem)."""
    if result.success:
        return result
    if result.status in _IPOPT_OK:
        found = from_rejection(result.verification)
    else:
        relaxed = relax(problem)
        found = from_relaxed(relaxed)
        if found.feasible:
            restarted = restart_from(problem, relaxed)
            if restarted.success:
                return restarted
    posture = {**result.posture, "diagnosis": found.to_dict()}
    return replace(result, diagnosis=found.line, posture=posture)


def restart_from(problem: Any, relaxed: Relaxed) -> Result:
    """``problem`` solved again (the active-set loop when it avoids collisions) from the
    relaxed solution, which met every row and passed the re-check: a start that IPOPT did
    not reach from the initial posture (ATLAS' third stair: 400 iterations from the second
    stair's posture, then restoration failed). When that run fails too, the relaxed posture
    itself: IPOPT converged on the elastic program with no row moved, and the posture passes
    every check of this problem. Its posture file notes which."""
    x0, layout = relaxed.x, relaxed.x_index
    program = Program.of(problem)
    if problem.collision_options is None:
        result = _result(program, run_nlp(program, x0, layout=layout))
    else:
        result = _solve_avoiding(program, x0, [], layout)[0]
    note = "solved again from the relaxed program's posture (the first start did not converge)"
    if not result.success:
        result = _result(relaxed.problem, [relaxed.run])
        note = (
            "the relaxed program's posture (IPOPT converged on the elastic program with no row "
            "moved; the problem itself did not converge from the initial posture nor from it)"
        )
    posture = {**result.posture, "notes": [*result.posture.get("notes", []), note]}
    return replace(result, posture=posture)


def solve_diagnosed(problem: Any) -> Result:
    """:func:`posturegen.solver.solve.solve`, and the diagnosis of a failure: what the command line
    runs."""
    return diagnose(problem, solve(problem))


def relax(problem: Any) -> Relaxed:
    """The elastic solve, on copies of ``problem``: first every task, torque limit, contact
    and friction row relaxed, without collision avoidance; when that needs no row to move and
    the problem avoids collisions, only the collision rows relaxed, from that posture (so that
    what only a collision blocks is named as such, and a foot fixed inside a box is not
    reported as the foot moving away from it)."""
    first = _elastic_run(problem, Elastic(), None, None)
    opts = problem.collision_options
    if opts is None or causes(first) or not first.converged:
        return first
    return _elastic_run(problem, COLLISION_ONLY, replace(opts, tighten=0), first)


def _elastic_run(problem: Any, elastic: Elastic, opts: Any, start: Relaxed | None) -> Relaxed:
    """One elastic solve of a copy of ``problem`` with collision options ``opts`` (the
    active-set loop when given, without margin growth), from the problem's initial guess or
    ``start``'s solution."""
    solver = problem.solver_options
    relaxed = replace(
        problem,
        elastic=elastic,
        collision_options=opts,
        # a one-off structure: CasADi's virtual machine, no compilation to C
        solver_options=replace(
            solver, max_iter=max(solver.max_iter, ELASTIC_MAX_ITER), codegen="off", jit=False
        ),
    )
    x0, layout = (None, None) if start is None else (start.x, start.x_index)
    if opts is None:
        run = run_nlp(Program.of(relaxed), x0, layout=layout)[-1]
    else:
        run = _solve_avoiding(Program.of(relaxed), x0, [], layout)[1][-1]
    q = configuration_from_x(relaxed, run.compiled, run.x)
    return Relaxed(run.program, run, _outputs(run), q)


def from_relaxed(relaxed: Relaxed) -> Diagnosis:
    """The causes read from an elastic solution, strongest first, and the one-line summary."""
    found = causes(relaxed)
    if not found:
        return _unblocked(relaxed)
    main = [c for c in found if c.penalty >= MAIN_SHARE * found[0].penalty]
    line = "; ".join(c.text for c in main[:MAX_CAUSES])
    if len(main) > MAX_CAUSES:
        line += f"; and {len(main) - MAX_CAUSES} more (posture file: diagnosis)"
    if not relaxed.converged:
        line += f" (the relaxed solve stopped: {relaxed.status})"
    return Diagnosis(line, found, relaxed.status, False)


def _unblocked(relaxed: Relaxed) -> Diagnosis:
    """No row had to move (beyond the tolerances TOL_*); ``feasible`` when the relaxed
    solution passes the re-check."""
    feasible = relaxed.converged and relaxed.verified()
    if not relaxed.converged:
        how = f"IPOPT did not converge on the relaxed program either ({relaxed.status})"
    elif feasible:
        how = (
            "the relaxed program found a posture that passes the re-check, which IPOPT did "
            "not reach from the initial posture (try another options.initial)"
        )
    else:
        how = (
            "the relaxed program moved no row by more than 1 mm (0.5 % of a torque limit), "
            "IPOPT did not reach a posture from the initial one (try another options.initial)"
        )
    return Diagnosis(f"no constraint blocks it: {how}", (), relaxed.status, feasible)


def from_rejection(report: Any) -> Diagnosis:
    """IPOPT converged but the re-check (a :class:`posturegen.verify.VerifyReport`) failed."""
    causes = tuple(
        Cause(
            "check",
            c.name,
            float(c.value),
            "",
            f"{c.name} {c.value:.3g} > {c.tolerance:.1g}" + (f" ({c.detail})" if c.detail else ""),
        )
        for c in report.failures
    )
    line = "IPOPT's posture fails the re-check: " + "; ".join(c.text for c in causes)
    return Diagnosis(line, causes)


def causes(r: Relaxed) -> tuple[Cause, ...]:
    """Every relaxed row block that had to move, the costliest first."""
    found = [
        *_task_causes(r),
        *_torque_causes(r),
        *_contact_causes(r),
        *_friction_causes(r),
        *_collision_causes(r),
    ]
    return tuple(sorted(found, key=lambda c: -c.penalty))


def _length(x: float) -> str:
    """A length [m] to three significant digits, whole metres from 10 m on."""
    return f"{x:.3g}" if x < 10 else f"{x:.0f}"


def _penalty(r: Relaxed, block: str, slack: np.ndarray) -> float:
    return float((r.elastic.weight(block) or 0.0) * np.abs(slack).sum())


def _task_causes(r: Relaxed) -> Iterator[Cause]:
    for t in r.problem.tasks:
        slacks = {
            k[len(t.name) + 1 :]: v for k, v in r.slacks.items() if k.startswith(f"{t.name}.")
        }
        position = slacks.pop("position", None)
        if position is not None and np.linalg.norm(position) > TOL_LENGTH:
            gap = float(np.linalg.norm(position))
            pen = _penalty(r, t.name, position)
            yield Cause("task", f"task {t.index}", gap, "m", _reach_text(r, t, gap), pen)
        rot = [slacks.pop(k) for k in ("orientation", "orientation_branch") if k in slacks]
        if rot and max(np.abs(v).max() for v in rot) > TOL_SINE:
            yield _orientation_cause(r, t, rot)
        for block, v in slacks.items():
            amount = float(np.abs(v).max())
            if amount > TOL_SINE:
                text = t.blocked(block, amount)
                yield Cause("task", f"task {t.index}", amount, t.unit, text, _penalty(r, t.name, v))


def _reach_text(r: Relaxed, t: Task, gap: float) -> str:
    """A task's position block relaxed by ``gap`` [m]: its target beyond reach, inside an
    obstacle, or given in millimetres."""
    text = f"target of task {t.index} is {_length(gap)} m beyond reach of {t.subject()}"
    target = t.target_point()
    if target is None:
        return text
    far = float(np.linalg.norm(target - r.problem.q_init[0:3]))
    if far > MILLIMETRE_DISTANCE and far / 1000 < MILLIMETRE_DISTANCE / 4:
        text += f" (it is {_length(far)} m from the robot: millimetres? targets are in m)"
    box = _obstacle_at(r.problem.scene.obstacles, target)
    if box is not None:
        text = (
            f"target of task {t.index} is inside obstacle '{box}' ({t.subject()} stays "
            f"{_length(gap)} m from it)"
        )
    return text


def _orientation_cause(r: Relaxed, t: Task, rot: list[np.ndarray]) -> Cause:
    """A task's orientation rows relaxed: the angle [deg] it stays from its target."""
    pen = sum(_penalty(r, t.name, v) for v in rot)
    R_target = getattr(t, "R_target", None)
    rotation = r.outputs.get(f"{t.name}.rotation")
    if R_target is None or rotation is None:
        amount = float(max(np.abs(v).max() for v in rot))
        return Cause(
            "task", f"task {t.index}", amount, t.unit, t.blocked("orientation", amount), pen
        )
    R = rotation.reshape(3, 3, order="F")
    angle = np.degrees(np.linalg.norm(pin.log3(np.asarray(R_target).T @ R)))
    text = f"orientation of task {t.index} is {angle:.3g}° beyond reach of {t.subject()}"
    return Cause("task", f"task {t.index}", float(angle), "deg", text, pen)


def _obstacle_at(boxes: Any, point: Any) -> str | None:
    """The name of the first box (an Obstacle, full ``size``, or an EnvBox, ``half``) that
    contains a world point (3,), None if none does."""
    for o in boxes:
        half = np.asarray(o.size) / 2 if hasattr(o, "size") else np.asarray(o.half)
        local = o.T_world_box.rotation.T @ (np.asarray(point) - o.T_world_box.translation)
        if np.all(np.abs(local) <= half):
            return str(o.name)
    return None


def _torque_causes(r: Relaxed) -> Iterator[Cause]:
    s = r.slacks.get(TORQUE_LIMITS)
    if s is None:
        return
    robot = r.problem.robot
    finite = np.flatnonzero(np.isfinite(robot.effort_limit))
    scale = r.problem.torque_limit_scale
    for k in np.flatnonzero(np.abs(s) > TOL_TORQUE * scale):
        name = robot.joint_names[finite[k]]
        pct = 100.0 * abs(float(s[k])) / scale
        text = f"torque limit of {name} exceeded by {pct:.0f} %"
        yield Cause("torque", name, pct, "%", text, _penalty(r, TORQUE_LIMITS, s[k : k + 1]))


# contact blocks: (row kind, rows measuring a length [m] (others: sines of angles))
_PLACEMENT = ("position", "orientation", "coplanarity", "normals_opposite", "yaw_range")
_INSIDE = ("ellipse_inside", "inclusion", "point_inside")


def _contact_causes(r: Relaxed) -> Iterator[Cause]:
    for c in r.problem.contacts:
        pre = f"contact.{c.name}"
        s = {
            k: r.slacks[f"{pre}.{k}"]
            for k in (*_PLACEMENT, *_INSIDE, "ellipse_size")
            if f"{pre}.{k}" in r.slacks
        }
        parts = _contact_parts(s)
        if parts:
            amount = max(float(np.abs(v).max()) for v in s.values())
            pen = sum(_penalty(r, f"{pre}.{k}", v) for k, v in s.items())
            where = ("its pose on " if c.fixed_in_place else "") + f"surface '{c.surface.name}'"
            text = f"contact '{c.name}' cannot reach {where} ({', '.join(parts)})"
            yield Cause("contact", c.name, amount, "m", text, pen)


def _contact_parts(s: dict[str, np.ndarray]) -> list[str]:
    """The moves of one contact's rows, in words."""
    parts = []
    if "position" in s and np.linalg.norm(s["position"]) > TOL_LENGTH:
        parts.append(f"{_length(float(np.linalg.norm(s['position'])))} m away")
    if "coplanarity" in s and abs(s["coplanarity"][0]) > TOL_LENGTH:
        parts.append(f"{_length(abs(float(s['coplanarity'][0])))} m from its plane")
    tilt = [s[k] for k in ("orientation",) if k in s]
    tilt += [s["coplanarity"][1:]] if "coplanarity" in s else []
    if tilt and max(np.linalg.norm(v) for v in tilt) > TOL_SINE:
        sine = min(1.0, max(float(np.linalg.norm(v)) for v in tilt))
        parts.append(f"turned {np.degrees(np.arcsin(sine)):.3g}° from it")
    if "normals_opposite" in s and abs(s["normals_opposite"][0]) > TOL_SINE:
        parts.append("facing away from it")
    if "yaw_range" in s and abs(s["yaw_range"][0]) > TOL_SINE:
        parts.append("outside its yaw_range")
    inside = [float(np.abs(s[k]).max()) for k in _INSIDE if k in s]
    if inside and max(inside) > TOL_LENGTH:
        parts.append(f"{_length(max(inside))} m outside its polygon")
    if "ellipse_size" in s and np.abs(s["ellipse_size"]).max() > TOL_SINE:
        parts.append("its ellipse below min_radii or min_area")
    return parts


def _friction_causes(r: Relaxed) -> Iterator[Cause]:
    for c in r.problem.contacts:
        pre = f"contact.{c.name}"
        s = r.slacks.get(f"{pre}.friction")
        if s is None or np.abs(s).max() <= TOL_FORCE:
            continue
        forces = r.outputs[f"{pre}.forces"].reshape(3, -1, order="F").T  # (k, 3) world [N]
        grip = float(getattr(c, "grip", 0.0))  # [N] a hand's (posturegen.terms.forces)
        f = forces.sum(axis=0) @ c.surface.T_world_surface.rotation
        need = required_mu(f, c.friction, grip)
        held = f"μ = {c.mu:.2g}" + (f", grip {grip:.3g} N" if grip > 0 else "")
        text = f"friction at contact '{c.name}' needs μ >= {need:.2g} ({held})"
        yield Cause("friction", c.name, need, "mu", text, _penalty(r, f"{pre}.friction", s))


def required_mu(f: np.ndarray, friction: Any, grip: float = 0.0) -> float:
    """The least μ whose friction model (a :class:`posturegen.terms.contacts.FrictionModel`) holds
    the force f (3,) in the surface frame, pressed by ``grip`` beyond it (a hand's grip, same
    unit: the cone's apex moved by it, posturegen.terms.forces): with p = f_n + grip, |f_t|/p
    for the cone, max_k c_k·f_t/(cos(π/F)·p) over the F faces' directions c_k for the pyramid
    (inf when p <= 0)."""
    pressed = f[2] + grip
    if pressed <= 0:
        return float("inf")
    if friction.kind == "cone":
        return float(np.linalg.norm(f[:2]) / pressed)
    th = 2 * np.pi * np.arange(friction.faces) / friction.faces
    along = np.cos(th) * f[0] + np.sin(th) * f[1]
    return float(along.max() / (np.cos(np.pi / friction.faces) * pressed))


def _collision_causes(r: Relaxed) -> Iterator[Cause]:
    """One cause per pair of limbs (self rows) and per box (sphere-box rows), with the
    largest shortfall of its rows: a row that had to move by s puts its proxies margin - s
    apart (in its own smooth, conservative distance)."""
    term = r.problem.collision_term
    if term is None:
        return
    model, pm = r.problem.robot.model, term.pm
    s = r.slacks.get("collision.self")
    if s is not None:
        data = scratch_data(model)
        pin.forwardKinematics(model, data, r.q)
        centers = pm.centers_world(model, data)
        for k, (_, members) in enumerate(term.self_groups()):
            if members and s[k] > TOL_LENGTH:
                pairs = np.array(members, dtype=int)
                i, j = pairs[int(np.argmin(pm.distances(centers, pairs[:, 0], pairs[:, 1])))]
                who = f"the proxies of {_link(model, pm, i)} and {_link(model, pm, j)}"
                pen = _penalty(r, "collision.self", s[k : k + 1])
                yield _collision_cause(who, "each other", float(s[k]), term.margin, pen)
    s = r.slacks.get("collision.joint_maps")
    if s is not None:
        yield from _map_causes(r, term, s)
    s = r.slacks.get("collision.env")
    if s is None:
        return
    env_rows = term.env_rows()
    for b, box in enumerate(term.boxes):
        rows = [
            k
            for k, pair in enumerate(env_rows)
            if pair is not None and pair[1] == b and s[k] > TOL_LENGTH
        ]
        if not rows:
            continue
        rows.sort(key=lambda k: -s[k])
        links = list(dict.fromkeys(_link(model, pm, env_rows[k][0]) for k in rows))
        who = "the proxies of " + ", ".join(links[:3])
        more = len(links) - 3
        who += f" (and {more} more link{'s' if more > 1 else ''})" if more > 0 else ""
        pen = _penalty(r, "collision.env", s[rows])
        cause = _collision_cause(who, box_label(box), float(s[rows[0]]), term.margin, pen)
        inside = [
            t.index
            for t in r.problem.tasks
            if t.target_point() is not None and _obstacle_at([box], t.target_point()) is not None
        ]
        if inside and box.name in {o.name for o in r.problem.scene.obstacles}:
            cause = replace(cause, text=cause.text + f" (task {inside[0]}'s target is inside it)")
        yield cause


def _map_causes(r: Relaxed, term: Any, s: np.ndarray) -> Iterator[Cause]:
    """One cause per joint map (posturegen.collision.joint_maps) whose rows had to move: its
    two joints would have to enter the region of their plane where its links' meshes meet."""
    model, start = r.problem.robot.model, 0
    for m, on in term.map_rows():
        rows = s[start : start + len(m.discs)]
        start += len(m.discs)
        if on and rows.max(initial=0.0) > TOL_LENGTH:
            a, b = (_joint_link(model, j) for j in m.joints)
            text = (
                f"the meshes of {a} and {b} would meet (their two joints inside the region "
                "where they do, collision.joint_maps)"
            )
            pen = _penalty(r, "collision.joint_maps", rows)
            yield Cause("collision", f"{a} / {b}", float(rows.max()), "", text, pen)


def _collision_cause(who: str, other: str, slack: float, margin: float, penalty: float) -> Cause:
    """``who`` had to come ``slack`` [m] closer to ``other`` than the margin allows."""
    d = margin - slack
    if d < 0:
        text = f"{who} would have to overlap {other} by {100 * -d:.2g} cm"
    else:
        text = (
            f"{who} would have to come within {100 * d:.2g} cm of {other} "
            f"(collision_margin {100 * margin:.2g} cm)"
        )
    return Cause("collision", f"{who} / {other}", slack, "m", text, penalty)


def _link(model: pin.Model, pm: Any, sphere: int) -> str:
    """The name of the link (body frame) carrying a proxy sphere."""
    return _joint_link(model, pm.spheres[sphere].joint_id)


def _joint_link(model: pin.Model, joint: int) -> str:
    """The name of the link (body frame) a joint moves."""
    for f in model.frames:
        if f.parentJoint == joint and f.type == pin.FrameType.BODY:
            return str(f.name)
    return str(model.names[joint])
