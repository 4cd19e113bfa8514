"""Plans as a user meets them: ``posturegen plan`` run as a command, cold and warm.

A plan family is a scene (a shipped one by name, or a problem file of ``examples/plans`` with
its goal and rules files) and a robot. Each is planned three times by ``posturegen plan``,
each in a fresh process with the default budgets: *cold*, with an empty ``POSTUREGEN_CACHE``
(no compiled solver; a shipped robot's fitted proxies come from the package; the planner's
generated-C mode ``cached`` then runs the virtual machine and compiles nothing); then with
``POSTUREGEN_CODEGEN=auto``, which compiles every structure it meets into the cache (its wall
time reported as the *compiling run*); then *warm*, in that cache, the planner's own mode
again: each structure whose library is on disk runs generated C. A row gives whether the
goal was reached and every posture verified, the stages, postures and transitions, the
process's wall time, the plan's own split of it (plan.json's ``time``) and the worst contact
quality along the path (the smallest loaded region's inradius and the shallowest centre of
pressure).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError


@dataclass(frozen=True)
class PlanFamily:
    """``source``: a shipped scene's name, or the stem of a problem file of examples/plans
    (``stem.yaml``, ``stem.goal.yaml``, ``stem.rules.yaml`` if any)."""

    description: str
    source: str
    robot: str | None = None
    steps: int | None = None


PLAN_FAMILIES: dict[str, PlanFamily] = {
    "plan-stairs-atlas": PlanFamily("ATLAS, stairs of 4 steps", "stairs", "atlas", 4),
    "plan-stairs-talos": PlanFamily("Talos, stairs of 4 steps", "stairs", "talos", 4),
    "plan-ladder-vertical-hrp2": PlanFamily(
        "HRP-2, vertical ladder, feet to rung 2", "ladder-vertical", "hrp2"
    ),
    "plan-ladder-inclined-hrp2": PlanFamily(
        "HRP-2, inclined ladder, feet to step 2", "ladder-inclined", "hrp2"
    ),
    "plan-platform-talos": PlanFamily("Talos, a platform aside and turned", "platform"),
    "plan-stepping-stones-talos": PlanFamily("Talos, three stepping stones", "stepping_stones"),
    "plan-beam-talos": PlanFamily("Talos, a beam narrower than the sole", "beam"),
    "plan-high-step-talos": PlanFamily("Talos, a step 45 cm high", "high_step"),
    "plan-rail-step-talos": PlanFamily("Talos, a step 50 cm high, a hand on a rail", "rail_step"),
    "plan-platform-hrp2": PlanFamily("HRP-2, a platform aside and turned", "hrp2_platform"),
    "plan-ladder-platform-hrp2": PlanFamily(
        "HRP-2, a rung then a platform 40 cm up", "ladder_platform"
    ),
}


def examples_dir() -> Path:
    """examples/plans of the source tree this package runs from (a clone)."""
    return Path(__file__).resolve().parents[3] / "examples" / "plans"


@dataclass(frozen=True)
class PlanRun:
    """One ``posturegen plan`` process: its outcome and its numbers."""

    reached: bool
    verified: bool  # every posture of the written sequence passed its re-check
    stages: int
    postures: int
    tried: int
    wall_s: float  # the process, from its start to its exit
    time: dict[str, float] = field(default_factory=dict)  # plan.json's split
    min_region_cm: float = float("nan")
    min_cop_depth_cm: float = float("nan")
    stop: str = ""


@dataclass(frozen=True)
class PlanFamilyReport:
    """A plan family's cold run, its compiling run and its warm run."""

    family: str
    description: str
    cold: PlanRun
    compiling: PlanRun
    warm: PlanRun

    def line(self) -> str:
        """One line: outcome, stages, then each run's wall time and split."""
        c, w = self.cold, self.warm
        ok = "reached, all verified" if c.reached and c.verified else f"NOT reached ({c.stop})"
        return (
            f"{self.family}: {ok}; {c.stages} stages, {c.postures} postures, {c.tried} "
            f"transitions; cold {c.wall_s:.1f} s (solver {c.time.get('solver_s', 0):.1f}, "
            f"builds {c.time.get('build_s', 0):.1f}), warm {w.wall_s:.1f} s ({w.stages} "
            f"stages; compiling run {self.compiling.wall_s:.0f} s); worst region "
            f"{c.min_region_cm:.1f} cm, CoP depth {c.min_cop_depth_cm:.1f} cm"
        )


def plan_command(name: str, out: Path) -> list[str]:
    """The ``posturegen plan`` command of a family, writing to ``out``."""
    fam = PLAN_FAMILIES[name]
    cmd = [sys.executable, "-m", "posturegen.cli", "plan"]
    if fam.robot is not None:
        cmd += [fam.source, "--robot", fam.robot]
        if fam.steps is not None:
            cmd += ["--steps", str(fam.steps)]
    else:
        folder = examples_dir()
        start = folder / f"{fam.source}.yaml"
        if not start.is_file():
            raise InputError(
                "--family", f"{name} needs {start}", "run the bench from a clone of posturegen"
            )
        cmd += [str(start), "--goal", str(folder / f"{fam.source}.goal.yaml")]
        rules = folder / f"{fam.source}.rules.yaml"
        if rules.is_file():
            cmd += ["--rules", str(rules)]
    return [*cmd, "--out", str(out), "--quiet", "--no-figures"]


def _run(name: str, cache: Path, out: Path, codegen: str | None = None) -> PlanRun:
    """One plan of the family in a fresh process on ``cache`` (``codegen``: its
    $POSTUREGEN_CODEGEN; None: the planner's own mode)."""
    env = {**os.environ, "POSTUREGEN_CACHE": str(cache)}
    env.pop("POSTUREGEN_CODEGEN", None)
    if codegen is not None:
        env["POSTUREGEN_CODEGEN"] = codegen
    t0 = time.perf_counter()
    proc = subprocess.run(plan_command(name, out), env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    summary_file = out / "plan.json"
    if proc.returncode not in (0, 1) or not summary_file.is_file():
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        return PlanRun(False, False, 0, 0, 0, wall, stop=f"exit {proc.returncode}: {tail[0]}")
    summary = json.loads(summary_file.read_text())
    index = json.loads((out / "sequence.json").read_text())
    quality = summary["quality"]
    return PlanRun(
        reached=bool(summary["reached"]),
        verified=all(s["success"] for s in index["stages"]),
        stages=len(index["stages"]),
        postures=int(summary["postures_solved"]),
        tried=int(summary["transitions_tried"]),
        wall_s=wall,
        time=dict(summary.get("time", {})),
        min_region_cm=100 * float(quality["min_region_inradius_m"]),
        min_cop_depth_cm=100 * float(quality["min_cop_depth_m"]),
        stop=str(summary["stop"]),
    )


def run_plan_family(name: str, folder: Path | None = None) -> PlanFamilyReport:
    """The family planned cold (an empty cache), compiling, then warm (the same cache), each
    in a fresh process; their files under ``folder`` (a temporary one by default)."""
    if name not in PLAN_FAMILIES:
        raise InputError("--family", f"unknown plan family '{name}'", ", ".join(PLAN_FAMILIES))
    root = Path(folder or tempfile.mkdtemp(prefix="posturegen-plans-")) / name
    cache = root / "cache"
    cache.mkdir(parents=True, exist_ok=True)
    cold = _run(name, cache, root / "cold")
    compiling = _run(name, cache, root / "compiling", codegen="auto")
    warm = _run(name, cache, root / "warm")
    return PlanFamilyReport(name, PLAN_FAMILIES[name].description, cold, compiling, warm)


def plan_table(reports: list[PlanFamilyReport]) -> list[str]:
    """Markdown rows of the plan families."""
    head = (
        "| family | what | reached, verified | stages | postures | transitions | cold [s] "
        "| of which solver / builds [s] | warm [s] (stages) | compiling run [s] "
        "| worst region [cm] | worst CoP depth [cm] |"
    )
    lines = [head, "|" + "---|" * 12]
    for r in reports:
        c, w = r.cold, r.warm
        ok = "yes" if c.reached and c.verified else f"no: {c.stop}"
        split = f"{c.time.get('solver_s', 0):.1f} / {c.time.get('build_s', 0):.1f}"
        warm_ok = "" if w.reached and w.verified else ", not reached"
        lines.append(
            f"| `{r.family}` | {r.description} | {ok} | {c.stages} | {c.postures} | {c.tried} "
            f"| {c.wall_s:.1f} | {split} | {w.wall_s:.1f} ({w.stages}{warm_ok}) "
            f"| {r.compiling.wall_s:.0f} | {c.min_region_cm:.1f} | {c.min_cop_depth_cm:.1f} |"
        )
    return lines
