"""Why a plan's best stance does not hold its goal: per goal contact it lacks, the rule, the
reach, the transition that failed (with its reason) or the budget that kept it off."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from .heuristic import Heuristic
from .layout import anchor_points, pick_target
from .node import Node
from .rules import Rules


def blocked_lines(
    node: Node,
    heur: Heuristic,
    rules: Rules,
    failures: Sequence[Mapping[str, str]],
    stop: str,
) -> list[str]:
    """One line per goal contact the stance lacks (``patch on surface: why``); the search's
    ``stop`` for a frame goal. ``failures``: the search's failed transitions (``stance``,
    ``action``, ``why``)."""
    on = dict(node.key)
    out = []
    for p, s in heur.goal.contacts:
        if on.get(p) != s:
            out.append(f"{p} on {s}: {_why_not(node, p, s, heur, rules, failures, stop)}")
    if not heur.goal.contacts:
        out.append(f"{heur.goal.describe()}: {stop}")
    return out


def _why_not(
    node: Node,
    patch: str,
    surface: str,
    heur: Heuristic,
    rules: Rules,
    failures: Sequence[Mapping[str, str]],
    stop: str,
) -> str:
    rule = rules.patches.get(patch)
    if rule is None or not rule.allows(surface):
        return "the rules do not let this patch on this surface (rules.patches)"
    if patch not in rules.movable():
        return "hands are not used (rules.hands: false)"
    tried = [
        f["why"]
        for f in failures
        if f["stance"] == node.describe() and f["action"].startswith(f"{patch} ")
    ]
    if tried:
        return "failed: " + tried[-1]
    on = dict(node.key)
    anchors = anchor_points([x for x in node.key if x[0] != patch], node.positions)
    region = heur.areas[surface]
    if anchors and pick_target(region, heur.spots[patch], anchors, rule.reach) is None:
        d = min(region.distance(a) for a in anchors)
        return (
            f"beyond the patch's reach ({rule.reach:.2f} m, rules.patches.{patch}.reach) "
            f"of the other contacts: {d:.2f} m away"
        )
    if patch in on:
        return f"not tried from here (the patch is on {on[patch]}; {stop})"
    return f"not tried ({stop})"
