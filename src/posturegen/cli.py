"""Command line: ``posturegen solve | verify | demo | bench``.

Exit codes: 0 verified success; 1 no posture found (the file is still written, success false);
2 invalid input (one line on stderr naming the field and the fix).
"""

from __future__ import annotations

import argparse
import importlib.resources
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from .errors import PosturegenError

EXIT_OK, EXIT_NOT_FOUND, EXIT_INPUT = 0, 1, 2


def _demo_dir() -> Path:
    return Path(str(importlib.resources.files("posturegen") / "data" / "demos"))


def demo_names() -> list[str]:
    """Names of the shipped demo problems."""
    return sorted(p.stem for p in _demo_dir().glob("*.yaml"))


def _solve_to(problem_path: Path, out: Path, quiet: bool = False) -> int:
    from .solve import solve
    from .spec import load_problem

    problem = load_problem(problem_path)
    result = solve(problem)
    path = result.write(out / "posture.json")
    if not quiet:
        state = "verified posture" if result.success else "NO POSTURE"
        print(
            f"{state}: {result.message}; IPOPT {result.status}, {result.iterations} iterations, "
            f"{1e3 * result.solve_time_s:.1f} ms (+{1e3 * result.build_time_s:.0f} ms build)"
        )
        print(f"wrote {path}")
    return EXIT_OK if result.success else EXIT_NOT_FOUND


def cmd_solve(args: argparse.Namespace) -> int:
    """posturegen solve PROBLEM.yaml --out DIR"""
    return _solve_to(Path(args.problem), Path(args.out), args.quiet)


def cmd_inspect(args: argparse.Namespace) -> int:
    """posturegen inspect PROBLEM.yaml: the program's variables, constraints and costs."""
    from .spec import load_problem

    print(load_problem(Path(args.problem)).summary())
    return EXIT_OK


def cmd_verify(args: argparse.Namespace) -> int:
    """posturegen verify POSTURE.json"""
    from .verify import verify_file

    report = verify_file(args.posture)
    print(report.summary())
    print("posture verified" if report.ok else "posture REJECTED")
    return EXIT_OK if report.ok else EXIT_NOT_FOUND


def cmd_demo(args: argparse.Namespace) -> int:
    """posturegen demo --list | posturegen demo NAME --out DIR"""
    from .spec import read_yaml

    names = demo_names()
    if args.list or args.name is None:
        for name in names:
            data = read_yaml(_demo_dir() / f"{name}.yaml")
            print(f"{name:<16} {data.get('description', '')}")
        return EXIT_OK
    if args.name not in names:
        raise PosturegenError(f"demo: unknown demo '{args.name}' (known: {', '.join(names)})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    src = _demo_dir() / f"{args.name}.yaml"
    (out / "problem.yaml").write_text(src.read_text())
    return _solve_to(src, out, args.quiet)


def cmd_bench(args: argparse.Namespace) -> int:
    """posturegen bench [--json FILE]"""
    from .bench import FAMILIES, run_family

    names = args.family or list(FAMILIES)
    for name in names:
        if name not in FAMILIES:
            raise PosturegenError(
                f"--family: unknown family '{name}' (known: {', '.join(FAMILIES)})"
            )
    reports = []
    for name in names:
        rep = run_family(name, args.n, args.seed, args.jit)
        print(rep.line(), flush=True)
        for failure in rep.failures[:5]:
            print(f"    failed {failure}")
        reports.append(rep)
    if args.json:
        from dataclasses import asdict

        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(r) for r in reports], indent=1))
    return EXIT_OK


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for tests and docs)."""
    parser = argparse.ArgumentParser(prog="posturegen", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("solve", help="solve a problem file, write DIR/posture.json")
    p.add_argument("problem")
    p.add_argument("--out", required=True)
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_solve)
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
    p.set_defaults(func=cmd_demo)
    p = sub.add_parser("bench", help="run the seeded benchmark families")
    p.add_argument("--json", help="also write the reports to this JSON file")
    p.add_argument("--family", action="append", help="run only this family (repeatable)")
    p.add_argument("-n", type=int, default=100, help="problems per family (default 100)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jit", action="store_true", help="compile the solvers to C first (needs gcc)")
    p.set_defaults(func=cmd_bench)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``posturegen`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except PosturegenError as exc:
        print(f"posturegen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:  # pragma: no cover - interactive
        print("posturegen: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
