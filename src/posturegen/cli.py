"""Command line: ``posturegen solve | batch | inspect | verify | demo | climb | plan | bench |
render | view``.

Exit codes: 0 verified success; 1 no posture found (the file is still written, success false);
2 invalid input (one line on stderr naming the field and the fix).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.resources
import importlib.util
import json
import os
import shutil
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TypeVar

from .batch.command import batch_to_dir
from .batch.sources import read_sources
from .bench.cold import COLD_FAMILIES, COLD_SEED, cold_table, run_cold, run_peer
from .bench.families import FAMILIES, FamilyReport, comparison_lines, run_families
from .bench.planner import PlannerReport, run_planner_family
from .bench.plans import PLAN_FAMILIES, plan_table, run_plan_family
from .bench.reach import PLANNER_FAMILIES
from .bench.scaling import DEFAULT_FAMILY, ScalingRow, batch_scaling, machine_line, table
from .bench.table import results_table, write_markdown
from .climb.scenes import SCENES, scene
from .climb.sequence import StageReport, run_sequence
from .errors import PosturegenError, PosturegenWarning
from .hints import with_hint
from .io.problem_file import load_problem, read_yaml
from .io.schema import add_parser as add_schema_parser
from .planner.command import add_parser as add_plan_parser
from .solver.diagnose import solve_diagnosed
from .solver.inspection import describe
from .solver.problem import DEFAULT_METHOD, METHODS
from .verify import verify_file

EXIT_OK, EXIT_NOT_FOUND, EXIT_INPUT = 0, 1, 2


def _demo_dir() -> Path:
    return Path(str(importlib.resources.files("posturegen") / "data" / "demos"))


def demo_names() -> list[str]:
    """Names of the shipped demo problems."""
    return sorted(p.stem for p in _demo_dir().glob("*.yaml"))


_SOLVER_NAMES = {"sqp": "SQP", "ipopt": "IPOPT"}  # how a Result's solver is printed


def _solve_to(problem_path: Path, out: Path, quiet: bool = False, png: str | None = None) -> int:

    result = solve_diagnosed(load_problem(problem_path))
    path = result.write(out / "posture.json")
    effort = (
        f"{_SOLVER_NAMES.get(result.method, result.method)} {result.status}, "
        f"{result.iterations} iterations, "
        f"{1e3 * result.solve_time_s:.1f} ms (+{1e3 * result.build_time_s:.0f} ms build)"
    )
    if not result.success:  # one line on stderr: what blocks it
        print(f"posturegen: no posture: {result.diagnosis} ({effort})", file=sys.stderr)
    elif not quiet:
        print(f"verified posture: {effort}")
    if not quiet:
        print(f"wrote {path}")
    if png is not None:
        from .viz import render_png

        figure = render_png(path, Path(png) if png else path.with_suffix(".png"))
        if not quiet:
            print(f"wrote {figure}")
    return EXIT_OK if result.success else EXIT_NOT_FOUND


def cmd_solve(args: argparse.Namespace) -> int:
    """posturegen solve PROBLEM.yaml --out DIR"""
    return _solve_to(Path(args.problem), Path(args.out), args.quiet, args.png)


def cmd_batch(args: argparse.Namespace) -> int:
    """posturegen batch PROBLEMS... --out DIR [--workers N] [--backend local|ray]"""
    problems = read_sources(args.problems, sys.stdin)
    out = Path(args.out)
    summary = batch_to_dir(problems, out, args.backend, args.workers, args.address, args.quiet)
    for line in summary.lines():
        print(line)
    if not args.quiet:
        print(f"wrote {out / 'batch.json'} and the posture files")
    return EXIT_OK if summary.verified == summary.n else EXIT_NOT_FOUND


def cmd_inspect(args: argparse.Namespace) -> int:
    """posturegen inspect PROBLEM.yaml: the program's variables, constraints and costs."""
    print(describe(load_problem(Path(args.problem))))
    return EXIT_OK


def cmd_verify(args: argparse.Namespace) -> int:
    """posturegen verify POSTURE.json"""
    report = verify_file(args.posture)
    print(report.summary())
    print("posture verified" if report.ok else "posture REJECTED")
    return EXIT_OK if report.ok else EXIT_NOT_FOUND


def cmd_demo(args: argparse.Namespace) -> int:
    """posturegen demo --list | posturegen demo NAME --out DIR [--robot NAME]"""
    names = demo_names()
    if args.list or args.name is None:
        for name, info in SCENES.items():
            print(f"{name:<16} [{info.robot}] {info.description}")
        for name in names:
            if name not in SCENES:
                data = read_yaml(_demo_dir() / f"{name}.yaml")
                print(f"{name:<16} {data.get('description', '')}")
        return EXIT_OK
    known = sorted(set(names) | set(SCENES))
    if args.name not in known:
        hint = with_hint(args.name, known, f"known: {', '.join(known)}")
        raise PosturegenError(f"demo: unknown demo '{args.name}' ({hint})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.name in names and args.robot is None:
        src = _demo_dir() / f"{args.name}.yaml"
        (out / "problem.yaml").write_text(src.read_text())
        return _solve_to(src, out, args.quiet, args.png)
    return _run_sequence(scene(args.name, args.robot), out, args.quiet, args.png, final=True)


def cmd_climb(args: argparse.Namespace) -> int:
    """posturegen climb SCENE --robot NAME --steps K --out DIR"""
    climbs = [n for n, info in SCENES.items() if info.climb_steps is not None]
    if args.scene not in climbs:
        hint = with_hint(args.scene, climbs, f"known: {', '.join(climbs)}")
        raise PosturegenError(f"climb: unknown climb '{args.scene}' ({hint})")
    steps = args.steps if args.steps is not None else SCENES[args.scene].climb_steps
    if steps is None or steps < 1:
        raise PosturegenError("--steps: expected an integer >= 1 (steps of each foot)")
    seq = scene(args.scene, args.robot, steps)
    return _run_sequence(seq, Path(args.out), args.quiet, args.png, final=False)


def _run_sequence(seq: dict, out: Path, quiet: bool, png: str | None, final: bool) -> int:
    """Run a sequence with a progress bar; with ``final`` also copy the last posture to
    DIR/posture.json. Exit 0 when every stage was verified, 1 otherwise (said on stderr)."""

    robot = seq["robot"] if isinstance(seq["robot"], str) else seq["robot"].get("name")
    t_start = time.perf_counter()

    def progress(k: int, n: int, name: str, rep: StageReport | None) -> None:
        if quiet:
            return
        done = k + (1 if rep is not None else 0)
        bar = "#" * round(24 * done / n) + "." * (24 - round(24 * done / n))
        elapsed = time.perf_counter() - t_start
        if rep is None:
            line = f"[{bar}] {k + 1}/{n} {name} ..."
            print(f"\r{line:<100}", end="", flush=True, file=sys.stderr)
            return
        r = rep.result
        state = "ok" if r.success else "FAILED"
        line = (
            f"[{bar}] {k + 1}/{n} {name}: {state}, {r.iterations} it, "
            f"{_SOLVER_NAMES.get(r.method, r.method)} "
            f"{1e3 * r.solve_time_s:.0f} ms, stage {rep.wall_time_s:.1f} s, "
            f"total {elapsed:.1f} s"
        )
        print(f"\r{line:<100}", file=sys.stderr, flush=True)

    report = run_sequence(seq, out, progress)
    last = report.stages[-1]
    if final:
        shutil.copyfile(out / last.posture_file, out / "posture.json")
    if png is not None:  # every stage's figure beside its posture, the last one also at FILE
        from .viz import render_png

        for st in report.stages:
            figure = render_png(out / st.posture_file, (out / st.posture_file).with_suffix(".png"))
        target = Path(png) if png else (out / "posture.png" if final else None)
        if target is not None:
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(figure, target)
        if not quiet:
            print(f"wrote {len(report.stages)} figures" + (f", {target}" if target else ""))
    if not quiet:
        print(f"wrote {out / 'sequence.json'} ({len(report.stages)} stages)")
    if report.success:
        if not quiet:
            print(f"{report.name} on {robot}: every stage verified")
        return EXIT_OK
    print(
        f"posturegen: {report.name} on {robot}: no posture at stage '{last.name}': "
        f"{last.diagnosis or last.result.message}; nothing after it was solved",
        file=sys.stderr,
    )
    return EXIT_NOT_FOUND


def cmd_render(args: argparse.Namespace) -> int:
    """posturegen render POSTURE.json [-o FILE.png]: the paper-style figure."""
    from .viz import render_png

    out = Path(args.out) if args.out else Path(args.posture).with_suffix(".png")
    path = render_png(
        args.posture,
        out,
        meshes=args.meshes,
        dpi=args.dpi,
        title=args.title,
        azimuth=args.azimuth,
        elevation=args.elevation,
    )
    print(f"wrote {path}")
    return EXIT_OK


def cmd_view(args: argparse.Namespace) -> int:
    """posturegen view POSTURE.json|SEQUENCE.json [-o FILE.html]: the interactive viewer."""
    from .viz import write_html

    out = Path(args.out) if args.out else Path(args.source).with_suffix(".html")
    path = write_html(args.source, out, meshes=args.meshes)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return EXIT_OK


def _add_png_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--png",
        nargs="?",
        const="",
        metavar="FILE",
        help="also draw the posture to FILE (default: DIR/posture.png; a climb draws every "
        "stage beside its posture file)",
    )


def cmd_bench(args: argparse.Namespace) -> int:
    """posturegen bench [--json FILE] [--markdown FILE] | posturegen bench --batch"""
    known = {**FAMILIES, **PLANNER_FAMILIES, **PLAN_FAMILIES}
    names = args.family or list(PLAN_FAMILIES if args.plans else FAMILIES | PLANNER_FAMILIES)
    for name in names:
        if name not in known:
            hint = with_hint(name, known, f"known: {', '.join(known)}")
            raise PosturegenError(f"--family: unknown family '{name}' ({hint})")
    if args.plans or any(name in PLAN_FAMILIES for name in names):
        return _bench_plans(args, names)
    if args.batch:
        return _bench_batch(args)
    if args.cold:
        return _bench_cold(args)
    args.n = 100 if args.n is None else args.n
    before = machine_line()

    def show(rep: FamilyReport | PlannerReport) -> None:
        print(rep.line(), flush=True)
        failures = rep.failures if isinstance(rep, FamilyReport) else rep.first.failures
        for failure in failures[:5]:
            print(f"    failed {failure}")

    classic = [name for name in names if name in FAMILIES]
    solvers = _solvers(args.solver)
    reports: list[FamilyReport] = []
    planner: list[PlannerReport] = []
    for solver in solvers:
        with _solver_env(solver):
            ran = run_families(classic, args.n, args.seed, args.jit, done=show)
            for line in comparison_lines(ran):
                print(line)
            reports += [_labelled(r, solver, solvers) for r in ran]
            for name in (name for name in names if name in PLANNER_FAMILIES):
                rep = run_planner_family(name, args.n, args.seed, args.jit)
                show(rep)
                planner.append(_labelled(rep, solver, solvers))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(r) for r in reports + planner], indent=1))
    if args.markdown:
        machine = f"{before} (after: load {machine_line().rsplit('load average ', 1)[1]})"
        write_markdown(args.markdown, results_table(machine, args.jit, reports, planner))
    return EXIT_OK


def _solvers(value: str) -> list[str]:
    """--solver's list (comma-separated), each checked."""
    solvers = [v.strip() for v in value.split(",") if v.strip()]
    for solver in solvers:
        if solver not in METHODS:
            raise PosturegenError(
                f"--solver: unknown solver '{solver}' (use {', '.join(METHODS)}, or several "
                "separated by commas)"
            )
    return solvers or [DEFAULT_METHOD]


@contextlib.contextmanager
def _solver_env(solver: str) -> Iterator[None]:
    """$POSTUREGEN_SOLVER set to ``solver`` (the families' problems leave method unset; the
    fresh processes of the planner and never-seen passes inherit it)."""
    previous = os.environ.get("POSTUREGEN_SOLVER")
    os.environ["POSTUREGEN_SOLVER"] = solver
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("POSTUREGEN_SOLVER", None)
        else:
            os.environ["POSTUREGEN_SOLVER"] = previous


R = TypeVar("R")


def _labelled(report: R, solver: str, solvers: list[str]) -> R:
    """``report`` with the solver after its family's name when the run compares solvers."""
    if len(solvers) < 2:
        return report
    return dataclasses.replace(report, family=f"{report.family} [{solver}]")  # type: ignore[type-var]


def _bench_plans(args: argparse.Namespace, names: list[str]) -> int:
    """posturegen bench --plans: each plan family by ``posturegen plan``, cold then warm."""
    others = [name for name in names if name not in PLAN_FAMILIES]
    if others:
        raise PosturegenError(f"--family: {others[0]} is not a plan family (--plans runs those)")
    before = machine_line()
    print(f"plans, each cold (an empty cache), compiling, then warm; default budgets: {before}")
    reports = []
    for name in names:
        reports.append(run_plan_family(name))
        print(reports[-1].line(), flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(r) for r in reports], indent=1))
    if args.markdown:
        after = machine_line().rsplit("load average ", 1)[1]
        head = f"Measured on {before} (after: load {after})."
        write_markdown(args.markdown, [head, "", *plan_table(reports)], "bench-plans")
    return EXIT_OK


def _bench_cold(args: argparse.Namespace) -> int:
    """posturegen bench --cold: the collision families on problems never seen, each in a
    fresh process with an empty cache, timed from the first call; with --peer, the same
    problems solved by the peer script (tools/drake_peer.sh) in the same run."""
    names = args.family or list(COLD_FAMILIES)
    for name in names:
        if name not in COLD_FAMILIES:
            raise PosturegenError(f"--family: --cold runs the families {', '.join(COLD_FAMILIES)}")
    n = 50 if args.n is None else args.n
    before = machine_line()
    print(f"never-seen pass, {n} problems per family, seed {COLD_SEED + args.seed}: {before}")
    folder = Path(tempfile.mkdtemp(prefix="posturegen-peer-"))
    reports, peers = [], []
    solvers = _solvers(args.solver)
    for name in names:
        problems = folder / f"{name}.jsonl" if args.peer else None
        for solver in solvers:
            with _solver_env(solver):
                report = run_cold(name, n, args.seed, problems)
            reports.append(_labelled(report, solver, solvers))
            print(reports[-1].line(), flush=True)
            for failure in reports[-1].failures[:5]:
                print(f"    failed {failure}")
        if args.peer and problems is not None:
            for peer in run_peer(args.peer, problems, folder / f"{name}.peer.jsonl"):
                peers.append(peer)
                print(peer.line(), flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(r) for r in reports + peers], indent=1))
    if args.markdown:
        after = machine_line().rsplit("load average ", 1)[1]
        head = f"Measured on {before} (after: load {after}); {n} problems per family."
        write_markdown(args.markdown, [head, "", *cold_table(reports, peers)], "bench-cold")
    return EXIT_OK


def _bench_batch(args: argparse.Namespace) -> int:
    """posturegen bench --batch: postures/s on 1..N local workers and on Ray."""
    if args.family and len(args.family) > 1:
        raise PosturegenError("--family: --batch runs one family (give --family once)")
    family = args.family[0] if args.family else DEFAULT_FAMILY
    if family not in FAMILIES:
        raise PosturegenError(f"--family: --batch runs a family of {', '.join(FAMILIES)}")
    n = 500 if args.n is None else args.n
    ray = importlib.util.find_spec("ray") is not None
    print(f"batch scaling, {family}, {n} problems, seed {args.seed}: {machine_line()}")
    if not ray:
        print("ray: not installed, no Ray row (pip install 'posturegen[ray]')")

    def show(row: ScalingRow) -> None:
        print(f"  {row.backend} x{row.workers}: {row.rate:.1f} postures/s", flush=True)

    rows = batch_scaling(family, n, args.seed, args.jit, ray, done=show)
    for line in table(rows):
        print(line)
    print(f"after: {machine_line()}")
    if args.markdown:
        head = f"{family}, {n} problems, seed {args.seed}: {machine_line()}"
        write_markdown(args.markdown, [head, "", *table(rows)], "bench-batch")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(r) for r in rows], indent=1))
    return EXIT_OK


def _add_batch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help="solve many problems on every core or a Ray cluster")
    p.add_argument("problems", nargs="+", help="problem files, folders of them, - for stdin")
    p.add_argument("--out", required=True)
    p.add_argument("--workers", type=int, help="processes (default: every core or Ray CPU)")
    p.add_argument("--backend", choices=["local", "ray"], default="local")
    p.add_argument("--address", help="Ray cluster: auto, or ray://HOST:10001 (default: local)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_batch)


def _add_bench_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="run the seeded benchmark families")
    p.add_argument("--json", help="also write the reports to this JSON file")
    p.add_argument(
        "--markdown",
        metavar="FILE",
        help="also write the results table to FILE (between its <!-- bench:start --> and "
        "<!-- bench:end --> lines if it has them; bench-batch for --batch)",
    )
    p.add_argument("--family", action="append", help="run only this family (repeatable)")
    p.add_argument(
        "-n", type=int, help="problems per family (default 100; --batch: 500 in each row)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jit", action="store_true", help="compile the solvers to C first (needs gcc)")
    p.add_argument(
        "--solver",
        default=DEFAULT_METHOD,
        help="the solver of every problem: auto (default: the SQP, IPOPT when it fails), sqp "
        "or ipopt; several separated by commas run one after the other (sqp,ipopt)",
    )
    p.add_argument(
        "--batch",
        action="store_true",
        help="postures/s of one family (default talos-stand-reach) in-process, on 1..N local "
        "workers and on Ray",
    )
    p.add_argument(
        "--cold",
        action="store_true",
        help="the collision families on problems never seen: each in a fresh process with an "
        "empty cache, timed from its first call (default 50 problems each)",
    )
    p.add_argument(
        "--plans",
        action="store_true",
        help="the plan families (plan-...): posturegen plan on each, cold (an empty cache) "
        "then warm; --family plan-... runs one",
    )
    p.add_argument(
        "--peer",
        metavar="COMMAND",
        help="with --cold: also solve the same problems with this peer (tools/drake_peer.sh)",
    )
    p.set_defaults(func=cmd_bench)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and docs)."""
    parser = argparse.ArgumentParser(prog="posturegen", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("solve", help="solve a problem file, write DIR/posture.json")
    p.add_argument("problem")
    p.add_argument("--out", required=True)
    p.add_argument("--quiet", action="store_true")
    _add_png_option(p)
    p.set_defaults(func=cmd_solve)
    _add_batch_parser(sub)
    p = sub.add_parser("inspect", help="print a problem's variables, constraints and costs")
    p.add_argument("problem")
    p.set_defaults(func=cmd_inspect)
    p = sub.add_parser("verify", help="re-check a posture file with Pinocchio")
    p.add_argument("posture")
    p.set_defaults(func=cmd_verify)
    p = sub.add_parser("demo", help="list or run a shipped demo problem")
    p.add_argument("name", nargs="?")
    p.add_argument("--list", action="store_true")
    p.add_argument("--out", default="out")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--robot", help="robot name (talos, g1, romeo, hrp2, atlas)")
    _add_png_option(p)
    p.set_defaults(func=cmd_demo)
    p = sub.add_parser("climb", help="solve a scripted contact sequence (stairs, ladders)")
    p.add_argument("scene")
    p.add_argument("--robot", help="robot name (default: the scene's robot)")
    p.add_argument("--steps", type=int, help="how far to climb (steps of each foot)")
    p.add_argument("--out", default="out")
    p.add_argument("--quiet", action="store_true")
    _add_png_option(p)
    p.set_defaults(func=cmd_climb)
    add_plan_parser(sub)
    add_schema_parser(sub)
    _add_bench_parser(sub)
    meshes = {"choices": ["visual", "collision"], "default": "visual", "help": "robot meshes"}
    p = sub.add_parser("render", help="draw a posture file to a PNG (paper-style figure)")
    p.add_argument("posture")
    p.add_argument("-o", "--out", help="PNG file (default: the posture file's name, .png)")
    p.add_argument("--meshes", **meshes)
    p.add_argument("--dpi", type=float, default=100.0, help="100: 1600x900 pixels")
    p.add_argument("--title", help="the figure's title (default: robot, file and status)")
    p.add_argument(
        "--azimuth",
        type=float,
        help="camera azimuth from the robot's heading [deg] (default: chosen to show the "
        "robot and its contacts, -35 (front right) when nothing hides them)",
    )
    p.add_argument(
        "--elevation", type=float, default=18.0, help="camera elevation [deg] (default 18)"
    )
    p.set_defaults(func=cmd_render)
    p = sub.add_parser("view", help="write a posture or sequence file's 3-D viewer (one HTML)")
    p.add_argument("source", help="a posture file, or a sequence file (a climb's stances)")
    p.add_argument("-o", "--out", help="HTML file (default: the source's name, .html)")
    p.add_argument("--meshes", **meshes)
    p.set_defaults(func=cmd_view)
    return parser


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: object = None,
    line: str | None = None,
) -> None:
    """posturegen's warnings as one line on stderr (``posturegen: warning: ...``), others as
    Python shows them."""
    if issubclass(category, PosturegenWarning):
        print(f"posturegen: warning: {message}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``posturegen`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", PosturegenWarning)
            warnings.showwarning = _show_warning
            return int(args.func(args))
    except PosturegenError as exc:
        print(f"posturegen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:  # pragma: no cover - interactive
        print("posturegen: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
