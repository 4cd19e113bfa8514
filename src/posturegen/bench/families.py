"""Seeded benchmark families (``posturegen bench``).

Each family is a generator of problems of one structure. The report per family: success rate
(verified postures), median/min/max of IPOPT's own wall time, the median of the whole call
(build of the parameters, IPOPT, re-check; not the generation and compilation of C code, which
``--jit`` waits for once per structure and reports on its own), and the median iteration count.
Solvers are built once per structure before timing (the first solve is a warm-up and is not
counted).
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..io.problem_file import problem_from_dict
from ..model.robot import load_bundled
from ..solver import codegen
from ..solver.compile import symbolic
from ..solver.problem import Problem, Program
from ..solver.solve import solve


@dataclass(frozen=True)
class FamilyReport:
    """Statistics of one family."""

    family: str
    description: str
    n: int
    successes: int
    success_rate: float
    median_solve_ms: float
    min_solve_ms: float
    max_solve_ms: float
    median_call_ms: float
    median_iterations: float
    variables: int
    constraints: int  # median over the problems of the last IPOPT run's rows
    contact_rows: int  # constraint rows of the contacts' geometry (not friction)
    failures: tuple[str, ...]
    # generated C (``jit``): libraries compiled during the family and their compile wall time
    # (those found in the disk cache cost nothing); the solves that ran compiled code
    c_builds: int = 0
    c_build_s: float = 0.0
    c_solves: int = 0
    p90_call_ms: float = float("nan")  # 90th percentile of the whole call

    def line(self) -> str:
        """One human-readable line."""
        out = (
            f"{self.family:<24} n={self.n:<4} success={100 * self.success_rate:5.1f}%  "
            f"solve median={self.median_solve_ms:6.1f} ms  min={self.min_solve_ms:6.1f}  "
            f"max={self.max_solve_ms:7.1f}  call median={self.median_call_ms:6.1f} ms  "
            f"p90={self.p90_call_ms:6.1f}  "
            f"iterations median={self.median_iterations:.0f}  "
            f"vars={self.variables} rows={self.constraints} contact rows={self.contact_rows}"
        )
        if self.c_solves or self.c_builds:
            out += (
                f"  C: {self.c_solves}/{self.n} solves, {self.c_builds} built "
                f"({self.c_build_s:.1f} s)"
            )
        return out


def _stance(rng: np.random.Generator) -> tuple[list[float], list[float], float, float, float]:
    """Random stance: width [m], a global yaw and a yaw per foot [rad]."""
    width = rng.uniform(0.16, 0.34)
    yaw = rng.uniform(-np.pi, np.pi)
    yaw_l, yaw_r = yaw + rng.uniform(-0.25, 0.25), yaw + rng.uniform(-0.25, 0.25)
    side = np.array([-np.sin(yaw), np.cos(yaw)])
    centre = rng.uniform(-0.3, 0.3, 2)
    left = (centre + side * width / 2).tolist()
    right = (centre - side * width / 2).tolist()
    return left, right, yaw_l, yaw_r, yaw


_RIGHT_REACH = (
    ("torso_1_joint", -0.5, 0.5),
    ("torso_2_joint", -0.1, 0.5),
    ("arm_right_1_joint", -1.2, 0.6),
    ("arm_right_2_joint", -1.6, -0.1),
    ("arm_right_3_joint", -1.0, 1.0),
    ("arm_right_4_joint", -2.0, -0.1),
)
_LEFT_REACH = (
    ("arm_left_1_joint", -0.6, 1.2),
    ("arm_left_2_joint", 0.1, 1.6),
    ("arm_left_3_joint", -1.0, 1.0),
    ("arm_left_4_joint", -2.0, -0.1),
)


def _reachable_target(
    rng: np.random.Generator,
    frame: str,
    joint_ranges: tuple[tuple[str, float, float], ...],
    centre: tuple[float, float] | np.ndarray = (0.0, 0.0),
    yaw: float = 0.0,
) -> list[float]:
    """A target for ``frame`` from forward kinematics of Talos' half-sitting posture with the
    given joints drawn uniformly in their ranges [rad], moved to a stance centre and heading
    (hence reachable in practice)."""
    model = load_bundled("talos").model
    data = model.createData()
    q = load_bundled("talos").q_init.copy()
    for name, lo, hi in joint_ranges:
        q[model.joints[model.getJointId(name)].idx_q] = rng.uniform(lo, hi)
    pin.framesForwardKinematics(model, data, q)
    p = data.oMf[model.getFrameId(frame)].translation
    c, s = np.cos(yaw), np.sin(yaw)
    return [centre[0] + c * p[0] - s * p[1], centre[1] + s * p[0] + c * p[1], float(p[2])]


def talos_stand_reach(n: int, seed: int) -> Iterator[Problem]:
    """Talos, two fixed feet at random stance widths and yaws, a right-gripper target."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        left, right, yaw_l, yaw_r, yaw = _stance(rng)
        centre = (np.array(left) + np.array(right)) / 2
        target = _reachable_target(rng, "gripper_right_base_link", _RIGHT_REACH, centre, yaw)
        yield problem_from_dict(
            {
                "robot": "talos",
                "surfaces": [{"name": "ground", "vertices": [[-2, -2], [2, -2], [2, 2], [-2, 2]]}],
                "contacts": [
                    {
                        "robot_patch": "left_sole",
                        "surface": "ground",
                        "type": "fixed",
                        "position": left,
                        "yaw": yaw_l,
                    },
                    {
                        "robot_patch": "right_sole",
                        "surface": "ground",
                        "type": "fixed",
                        "position": right,
                        "yaw": yaw_r,
                    },
                ],
                "tasks": [
                    {"type": "position", "frame": "gripper_right_base_link", "target": target}
                ],
                "options": {"initial": _initial_at(centre, yaw)},
            }
        )


def step_family(
    depth: tuple[float, float], contact: dict[str, Any]
) -> Callable[[int, int], Iterator[Problem]]:
    """Talos, left foot fixed on the ground, the right foot on a random step of depth in
    ``depth`` [m] (the foot is 0.20 m long) as ``contact``, a reachable left-hand target."""

    def generate(n: int, seed: int) -> Iterator[Problem]:
        rng = np.random.default_rng(seed)
        for _ in range(n):
            d = rng.uniform(*depth)
            step = {
                "name": "step",
                "position": [
                    rng.uniform(0.2, 0.35),
                    rng.uniform(-0.2, -0.1),
                    rng.uniform(0.05, 0.2),
                ],
                "rpy": [0.0, 0.0, rng.uniform(-0.3, 0.3)],
                "vertices": [[-d / 2, -0.25], [d / 2, -0.25], [d / 2, 0.25], [-d / 2, 0.25]],
            }
            yield problem_from_dict(
                {
                    "robot": "talos",
                    "surfaces": [
                        {"name": "ground", "vertices": [[-2, -2], [2, -2], [2, 2], [-2, 2]]},
                        step,
                    ],
                    "contacts": [
                        {
                            "robot_patch": "left_sole",
                            "surface": "ground",
                            "type": "fixed",
                            "position": [0.0, 0.1],
                        },
                        {"robot_patch": "right_sole", "surface": "step", **contact},
                    ],
                    "tasks": [
                        {
                            "type": "position",
                            "frame": "gripper_left_base_link",
                            "target": _reachable_target(rng, "gripper_left_base_link", _LEFT_REACH),
                        }
                    ],
                }
            )

    return generate


def _stand(target: list[float], options: dict[str, Any], obstacles: list | None = None) -> Problem:
    """Talos standing on both feet (0.2 m apart) with a right-gripper target."""
    return problem_from_dict(
        {
            "robot": "talos",
            "surfaces": [{"name": "ground", "vertices": [[-2, -2], [2, -2], [2, 2], [-2, 2]]}],
            "obstacles": obstacles or [],
            "contacts": [
                {
                    "robot_patch": "left_sole",
                    "surface": "ground",
                    "type": "fixed",
                    "position": [0.0, 0.1],
                },
                {
                    "robot_patch": "right_sole",
                    "surface": "ground",
                    "type": "fixed",
                    "position": [0.0, -0.1],
                },
            ],
            "tasks": [{"type": "position", "frame": "gripper_right_base_link", "target": target}],
            "options": options,
        }
    )


def near_body_family(self_collision: bool) -> Callable[[int, int], Iterator[Problem]]:
    """Right-gripper targets close to the body: in front of the torso (x 0.10-0.30 m,
    y -0.10-0.10 m, z 0.85-1.15 m) or across to the opposite hip (x 0.10-0.25 m,
    y 0.05-0.25 m, z 0.55-0.80 m), half each."""

    def generate(n: int, seed: int) -> Iterator[Problem]:
        rng = np.random.default_rng(seed)
        for i in range(n):
            if i % 2 == 0:
                t = [rng.uniform(0.1, 0.3), rng.uniform(-0.1, 0.1), rng.uniform(0.85, 1.15)]
            else:
                t = [rng.uniform(0.1, 0.25), rng.uniform(0.05, 0.25), rng.uniform(0.55, 0.8)]
            yield _stand(t, {"self_collision": self_collision})

    return generate


def box_family(avoid: bool) -> Callable[[int, int], Iterator[Problem]]:
    """A 0.2 m box in front (x 0.40-0.50, y -0.35 to -0.15, z 0.95-1.10 m) and a right-gripper
    target right under it (0.25-0.32 m below its centre, 0.15-0.22 m below its bottom)."""

    def generate(n: int, seed: int) -> Iterator[Problem]:
        rng = np.random.default_rng(seed)
        for _ in range(n):
            c = [rng.uniform(0.4, 0.5), rng.uniform(-0.35, -0.15), rng.uniform(0.95, 1.1)]
            t = [
                c[0] + rng.uniform(-0.05, 0.05),
                c[1] + rng.uniform(-0.05, 0.05),
                c[2] - rng.uniform(0.25, 0.32),
            ]
            box = [{"name": "box", "box": [0.2, 0.2, 0.2], "position": c}]
            yield _stand(t, {"environment_collision": avoid}, box)

    return generate


_SHORT, _DEEP = (0.08, 0.16), (0.26, 0.34)
_GEOM = {"type": "geometric", "min_radii": [0.03, 0.03]}


def _initial_at(centre: np.ndarray, yaw: float) -> list[float]:
    """Talos' half-sitting posture moved to a stance centre and heading."""
    q = load_bundled("talos").q_init.copy()
    q[0:2] = centre
    q[3:7] = pin.Quaternion(pin.utils.rotate("z", yaw)).coeffs()
    return q.tolist()


FAMILIES: dict[str, tuple[str, Callable[[int, int], Iterator[Problem]]]] = {
    "talos-stand-reach": (
        "Talos, two fixed feet, random stance width/yaws, reachable right-hand targets",
        talos_stand_reach,
    ),
    "talos-near-body-free": (
        "targets near the torso and the opposite hip, no collision avoidance (baseline)",
        near_body_family(False),
    ),
    "talos-near-body-collision": (
        "same problems with self-collision avoidance (meshes re-checked by coal)",
        near_body_family(True),
    ),
    "talos-box-free": (
        "a target under a box obstacle, the box not avoided (baseline)",
        box_family(False),
    ),
    "talos-box-collision": (
        "same problems, the box avoided (meshes re-checked by coal)",
        box_family(True),
    ),
    "talos-step-short-support": (
        "right foot on a step 8-16 cm deep (sole patch 18.5 cm): geometric contact, support form",
        step_family(_SHORT, {**_GEOM, "formulation": "support"}),
    ),
    "talos-step-short-paper": (
        "same problems: geometric contact, the paper's form (eqs. 4-6)",
        step_family(_SHORT, {**_GEOM, "formulation": "paper"}),
    ),
    "talos-step-short-inclusive": (
        "same problems: inclusive baseline (the foot fits only turned across the step)",
        step_family(_SHORT, {"type": "inclusive"}),
    ),
    "talos-step-deep-support": (
        "right foot on a step 26-34 cm deep (the foot fits): geometric, support form",
        step_family(_DEEP, {**_GEOM, "formulation": "support"}),
    ),
    "talos-step-deep-paper": (
        "same problems: geometric contact, the paper's form",
        step_family(_DEEP, {**_GEOM, "formulation": "paper"}),
    ),
    "talos-step-deep-inclusive": (
        "same problems: inclusive baseline (every foot vertex inside the step)",
        step_family(_DEEP, {"type": "inclusive"}),
    ),
}


# (baseline, variant) family pairs whose ratio a run reports: the same problems without and
# with collision avoidance (issue goal: median time <= 2x the baseline's)
COMPARISONS: tuple[tuple[str, str], ...] = (
    ("talos-near-body-free", "talos-near-body-collision"),
    ("talos-box-free", "talos-box-collision"),
)


def comparison_lines(reports: list[FamilyReport]) -> list[str]:
    """One line per pair of COMPARISONS whose two families are in ``reports``: the variant's
    median IPOPT time, whole-call time and iterations over the baseline's."""
    by_name = {r.family: r for r in reports}
    out = []
    for base, variant in COMPARISONS:
        if base in by_name and variant in by_name:
            a, b = by_name[base], by_name[variant]
            out.append(
                f"{variant} / {base}: solve {b.median_solve_ms / a.median_solve_ms:.2f}x  "
                f"call {b.median_call_ms / a.median_call_ms:.2f}x  "
                f"iterations {b.median_iterations / a.median_iterations:.2f}x"
            )
    return out


class _FamilyRun:
    """The seeded problems of one family, warmed up, solved one at a time (:meth:`step`) so
    that two families can be interleaved; :meth:`report` collects the statistics."""

    def __init__(self, name: str, n: int, seed: int, jit: bool) -> None:
        self.name, self.n = name, n
        self.description, generator = FAMILIES[name]
        self.problems = list(generator(n + 1, seed))
        for problem in self.problems:
            problem.solver_options = dataclasses.replace(
                problem.solver_options, codegen="sync" if jit else "off"
            )
        self.builds_before = len(codegen.BUILDS)
        solve(self.problems[0])  # warm-up: builds the solver for this structure
        # the layout of the family's program (no solver built: collision rows vary per run)
        self.compiled = symbolic(Program.of(self.problems[0]))
        self.times: list[float] = []
        self.calls: list[float] = []
        self.iters: list[int] = []
        self.rows: list[int] = []
        self.failures: list[str] = []
        self.ok = self.c_solves = 0

    def step(self, i: int) -> None:
        """Solve problem i (0-based, after the warm-up) and record it."""
        problem = self.problems[i + 1]
        builds = len(codegen.BUILDS)
        t0 = time.perf_counter()
        result = solve(problem)
        # the whole call but the C compiles it waited for (--jit: once per structure, counted
        # in c_builds and c_build_s)
        compiling = sum(b.generate_s + b.compile_s for b in codegen.BUILDS[builds:])
        self.calls.append(time.perf_counter() - t0 - compiling)
        self.rows.append(result.constraint_rows)  # the last run's (collision rows vary)
        self.c_solves += result.generated_c
        self.times.append(result.solve_time_s)
        self.iters.append(result.iterations)
        if result.success:
            self.ok += 1
        else:
            self.failures.append(f"#{i}: {result.message}")

    def report(self) -> FamilyReport:
        ms = [1e3 * t for t in self.times]
        compiled = self.compiled
        return FamilyReport(
            family=self.name,
            description=self.description,
            n=self.n,
            successes=self.ok,
            success_rate=self.ok / self.n,
            median_solve_ms=statistics.median(ms),
            min_solve_ms=min(ms),
            max_solve_ms=max(ms),
            median_call_ms=1e3 * statistics.median(self.calls),
            p90_call_ms=1e3 * float(np.percentile(self.calls, 90)),
            median_iterations=statistics.median(self.iters),
            variables=compiled.n_x,
            constraints=int(statistics.median(self.rows)),
            contact_rows=sum(
                s.stop - s.start
                for name, s in compiled.g_index.items()
                if name.startswith("contact.") and not name.endswith(".friction")
            ),
            failures=tuple(self.failures),
            c_builds=len(codegen.BUILDS) - self.builds_before,
            c_build_s=sum(b.compile_s for b in codegen.BUILDS[self.builds_before :]),
            c_solves=self.c_solves,
        )


def run_family(name: str, n: int = 100, seed: int = 0, jit: bool = False) -> FamilyReport:
    """Solve n seeded problems of a family and collect statistics. ``jit``: generated C
    (posturegen.solver.codegen, mode ``sync``: a structure's library is loaded from the disk cache
    or
    compiled before its first solve); else CasADi's virtual machine (mode ``off``), so that
    the numbers do not depend on when a background build ends."""
    family = _FamilyRun(name, n, seed, jit)
    for i in range(n):
        family.step(i)
    return family.report()


INTERLEAVE_BLOCK = 10  # problems per block when two compared families alternate


def run_families(
    names: list[str],
    n: int = 100,
    seed: int = 0,
    jit: bool = False,
    done: Callable[[FamilyReport], None] | None = None,
) -> list[FamilyReport]:
    """Reports of ``names`` in order (``done`` is called with each as it is ready). The two
    families of a pair of COMPARISONS, when both are asked for, are solved in alternating
    blocks of INTERLEAVE_BLOCK problems (problems 0-9 of the baseline, 0-9 of the variant,
    10-19 of the baseline...), so that the machine's slow and fast spells fall on both: on the
    2-core virtual machine a family's median moved by up to 40 % between separate runs. Blocks
    rather than single problems: alternating at every problem made the baseline 10-20 %
    slower (each solve ran after the other structure's code and data) and its ratio low."""
    reports: dict[str, FamilyReport] = {}
    paired = {
        name: (base, variant)
        for base, variant in COMPARISONS
        if base in names and variant in names
        for name in (base, variant)
    }
    for name in names:
        if name in reports:
            continue
        if name in paired:
            runs = [_FamilyRun(member, n, seed, jit) for member in paired[name]]
            for start in range(0, n, INTERLEAVE_BLOCK):
                for family in runs:
                    for i in range(start, min(n, start + INTERLEAVE_BLOCK)):
                        family.step(i)
            ready = [family.report() for family in runs]
        else:
            ready = [run_family(name, n, seed, jit)]
        for rep in ready:
            reports[rep.family] = rep
            if done is not None:
                done(rep)
    return [reports[name] for name in names]


def run(
    families: list[str] | None = None, n: int = 100, seed: int = 0, jit: bool = False
) -> list[dict[str, Any]]:
    """Run families (all by default); return their reports as dicts."""
    names = families or list(FAMILIES)
    return [asdict(r) for r in run_families(names, n, seed, jit)]
