"""``posturegen plan``: the command's progress line (stderr) and its summary lines."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TextIO

from ..viz import render_contact_sheet, write_html
from .api import PlanReport, plan
from .node import Node
from .search import Budget, Stats

EXIT_OK, EXIT_NOT_FOUND = 0, 1


class ProgressLine:
    """One line per event on ``stream``: transitions tried of the budget, postures solved,
    stances held, elapsed time, and what happened."""

    def __init__(self, budget: Budget, stream: TextIO | None = None) -> None:
        self.budget = budget
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = time.perf_counter()

    def __call__(self, stats: Stats, node: Node | None, event: str) -> None:
        n = self.budget.nodes
        done = min(24, round(24 * stats.tried / max(1, n)))
        bar = "#" * done + "." * (24 - done)
        elapsed = time.perf_counter() - self.t0
        h = f", h {node.h:.2f} m" if node is not None else ""
        line = (
            f"[{bar}] {stats.tried}/{n} tried, {stats.postures} postures, "
            f"{stats.held} held, {elapsed:.0f} s: {event}{h}"
        )
        print(line[:160], file=self.stream, flush=True)


def summary_lines(report: PlanReport, out: Path) -> list[str]:
    """What the command prints: the search's numbers, the stances found, the files."""
    s = report.stats
    q = report.quality
    lines = [
        f"{'reached' if s.reached else 'NOT reached'}: {report.goal.describe()} ({s.stop})",
        f"transitions tried {s.tried}, stances held {s.held}, nodes expanded {s.expanded}, "
        f"postures solved {s.postures}, {s.time_s:.1f} s",
        _time_line(report.summary["time"]),
        f"stages {len(report.sequence.stages)}; worst contact: region inradius "
        f"{100 * q.region:.1f} cm, CoP depth {100 * q.cop_depth:.1f} cm",
    ]
    lines += [f"  {t}" for t in report.summary["transitions"]]
    if not s.reached:
        lines.append(f"best stance found: {s.best}; what kept the goal from it:")
        lines += [f"  {b}" for b in s.blocked]
    lines.append(f"wrote {out / 'sequence.json'} and {out / 'plan.json'}")
    return lines


def _time_line(t: dict[str, float]) -> str:
    """``time 41.7 s: postures 38.2 s (solver 5.3, builds 30.1, ...), search 0.4 s, ...``."""
    return (
        f"time {t['total_s']:.1f} s: postures {t['postures_s']:.1f} s (solver "
        f"{t['solver_s']:.1f}, builds {t['build_s']:.1f}, verification {t['verify_s']:.1f}, "
        f"other {t['other_s']:.1f}), search {t['search_s']:.1f} s, files {t['files_s']:.1f} s"
    )


def write_figures(out: Path, meshes: str = "visual") -> list[str]:
    """The plan's viewer (``plan.html``: a slider over the stances) and contact sheet
    (``plan.png``) beside its sequence file; the line saying so, with their time."""
    sequence = out / "sequence.json"
    if not sequence.is_file():
        return []
    t0 = time.perf_counter()
    html = write_html(sequence, out / "plan.html", meshes=meshes)
    png = render_contact_sheet(sequence, out / "plan.png", meshes=meshes)
    took = time.perf_counter() - t0
    return [f"wrote {html} and {png} ({took:.1f} s, after the search)"]


def cmd_plan(args: argparse.Namespace) -> int:
    """posturegen plan SCENE_OR_PROBLEM --goal GOAL --out DIR"""
    budget = Budget(
        nodes=args.budget_nodes, seconds=args.budget_s, posture_iterations=args.budget_iter
    )
    out = Path(args.out)
    report = plan(
        args.source,
        out,
        goal=args.goal,
        rules=args.rules,
        robot=args.robot,
        steps=args.steps,
        budget=budget,
        workers=args.workers,
        progress=None if args.quiet else ProgressLine(budget),
    )
    lines = summary_lines(report, out)
    if not args.no_figures:
        lines += write_figures(out)
    for line in lines:
        print(line)
    return EXIT_OK if report.success else EXIT_NOT_FOUND


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``plan`` sub-command's arguments."""
    p = sub.add_parser("plan", help="search a contact sequence to a goal (stairs, ladders)")
    p.add_argument(
        "source",
        metavar="SCENE_OR_PROBLEM",
        help="stairs, ladder-inclined, "
        "ladder-vertical, or a problem file whose contacts are the start stance",
    )
    p.add_argument("--goal", help="goal file or JSON (default for a scene: both feet on its top)")
    p.add_argument("--rules", help="rules file or JSON (default: the robot's, the scene's)")
    p.add_argument("--out", required=True, help="directory for sequence.json and plan.json")
    p.add_argument("--robot", help="robot of a shipped scene")
    p.add_argument("--steps", type=int, help="size of a shipped scene (as for climb)")
    p.add_argument("--budget-nodes", type=int, default=Budget.nodes, help="transitions tried")
    p.add_argument("--budget-s", type=float, default=Budget.seconds, help="wall time [s]")
    p.add_argument(
        "--budget-iter",
        type=int,
        default=Budget.posture_iterations,
        help=f"IPOPT iterations of one posture, all its runs (default {Budget.posture_iterations})",
    )
    p.add_argument("--workers", type=int, default=1, help="processes solving sibling nodes")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--no-figures", action="store_true", help="write no plan.html (viewer) nor plan.png"
    )
    p.set_defaults(func=cmd_plan)
