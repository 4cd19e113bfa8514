"""A plan's files: the climb's (``NN-name.yaml`` problem and ``NN-name.json`` posture per
stage, ``sequence.json``, written by posturegen.sequence's writer) and ``plan.json``, the
search summary."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from ..climb.sequence import SequenceReport, StageReport, _slug, _write_index
from .node import Node
from .quality import Quality, posture_quality, worst
from .search import Budget, Stats
from .solver import Timing

PLAN_SCHEMA = "posturegen.plan/1"


def write_sequence(
    seq: Mapping[str, Any], path: list[Node], reached: bool, out: Path
) -> tuple[SequenceReport, Quality]:
    """Every stage of the path's nodes, in order, and ``sequence.json`` (``success`` only
    when the goal was reached); the worst contact quality over them."""
    out.mkdir(parents=True, exist_ok=True)
    report = SequenceReport(str(seq.get("name", "plan")))
    qualities = []
    k = 0
    for node in path:
        for stage in node.stages:
            stem = f"{k:02d}-{_slug(stage.name)}"
            (out / f"{stem}.yaml").write_text(yaml.safe_dump(stage.data, sort_keys=False))
            posture = dict(stage.result.posture)
            posture["stage"] = {"index": k, "name": stage.name, "sequence": report.name}
            (out / f"{stem}.json").write_text(json.dumps(posture, indent=1))
            r = stage.result
            wall = r.solve_time_s + r.build_time_s
            report.stages.append(StageReport(stage.name, f"{stem}.yaml", f"{stem}.json", r, wall))
            qualities.append(posture_quality(posture, stage.problem.robot))
            k += 1
    # an unreached goal: one stage more was planned than found, so success is false
    report.planned = len(report.stages) + (0 if reached else 1)
    _write_index(dict(seq), report, out)
    return report, worst(qualities)


def write_failed(stats: Stats, out: Path) -> None:
    """The problem of every failed transition posture as ``DIR/failed/NN-name.yaml`` (each
    solvable alone: ``posturegen solve`` diagnoses it)."""
    if not stats.failed_problems:
        return
    folder = out / "failed"
    folder.mkdir(parents=True, exist_ok=True)
    for k, (name, data) in enumerate(stats.failed_problems):
        (folder / f"{k:02d}-{_slug(name)}.yaml").write_text(yaml.safe_dump(data, sort_keys=False))


def plan_times(total: float, files: float, timing: Timing) -> dict[str, float]:
    """Where a plan's wall time went [s]: ``total``; ``postures_s``, the rounds of posture
    solves (the start's included), split (summed over the postures, across workers) into
    ``solver_s``, ``build_s``, ``verify_s`` and ``other_s``; ``search_s``, the rest of the
    search (successors, the heuristic, building problems); ``files_s``, writing them."""
    t = timing.to_dict()
    postures = t.pop("rounds_s")
    return {
        "total_s": round(total, 3),
        "postures_s": postures,
        **t,
        "search_s": round(max(0.0, total - postures - files), 3),
        "files_s": round(files, 3),
    }


def plan_summary(
    seq: Mapping[str, Any],
    goal: Mapping[str, Any],
    rules: Mapping[str, Any],
    budget: Budget,
    stats: Stats,
    path: list[Node],
    quality: Quality,
    times: Mapping[str, float],
) -> dict[str, Any]:
    """The content of ``plan.json`` (``times``: :func:`plan_times`)."""
    return {
        "schema": PLAN_SCHEMA,
        "name": seq.get("name", "plan"),
        "robot": seq["robot"] if isinstance(seq["robot"], str) else "custom",
        "goal": dict(goal),
        "rules": dict(rules),
        "budget": {
            "nodes": budget.nodes,
            "seconds": budget.seconds,
            "posture_iterations": budget.posture_iterations,
        },
        "reached": stats.reached,
        "stop": stats.stop,
        "best": stats.best,
        "blocked": list(stats.blocked),
        "transitions_tried": stats.tried,
        "stances_held": stats.held,
        "nodes_expanded": stats.expanded,
        "postures_solved": stats.postures,
        "hold_fallbacks": stats.hold_fallbacks,
        "unloads": stats.unloads,
        "time_s": stats.time_s,
        "time": dict(times),
        "stances": [n.describe() for n in path],
        "transitions": [n.action.label() if n.action else "start" for n in path],
        "quality": quality.to_dict(),
        "failures": stats.failures,
    }
