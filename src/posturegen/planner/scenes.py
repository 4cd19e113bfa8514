"""A shipped scene as a planning input: its first stance, its default goal (both soles on the
last surface its scripted climb puts a foot on) and its rules (which surfaces the soles and
hands may take; the contact options its climb uses for each patch). No stage list is used
beyond the first stance and the goal surface."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from ..climb.scenes import SCENES, scene
from ..errors import InputError
from ..hints import with_hint
from ..model.robot import Robot
from .rules import CONTACT_KEYS, PatchRule, Rules, default_rules, is_hand


@dataclass(frozen=True)
class ScenePlan:
    """Where a scene's soles and hands may go (fnmatch patterns), and how far it climbs."""

    soles: tuple[str, ...]
    hands: tuple[str, ...]
    steps: int


PLANS: dict[str, ScenePlan] = {
    "stairs": ScenePlan(("ground", "step*"), (), 4),
    "ladder-inclined": ScenePlan(("ground", "step*"), ("*_rail",), 1),
    "ladder-vertical": ScenePlan(("ground", "rung*"), ("rung*",), 0),
}


def plan_scene(name: str, robot: str | None, steps: int | None) -> dict[str, Any]:
    """The scene's sequence dict (its stages give the start stance and the goal surface)."""
    if name not in PLANS:
        known = list(PLANS)
        raise InputError(
            "scene",
            f"no plan for scene '{name}'",
            with_hint(name, known, f"use one of: {', '.join(known)}"),
        )
    return scene(name, robot or SCENES[name].robot, PLANS[name].steps if steps is None else steps)


def _placed(seq: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Every contact a stage places (not kept), in stage order."""
    return [c for stage in seq["stages"][1:] for c in stage["contacts"] if c.get("type") != "keep"]


def default_goal(seq: Mapping[str, Any]) -> dict[str, Any]:
    """Both soles on the last surface a sole is placed on by the scene's stages."""
    soles = [c for c in _placed(seq) if "sole" in c["robot_patch"]]
    top = soles[-1]["surface"] if soles else "ground"
    return {
        "contacts": [
            {"robot_patch": "left_sole", "surface": top},
            {"robot_patch": "right_sole", "surface": top},
        ]
    }


def _options(contacts: list[dict[str, Any]], hand: bool) -> tuple[dict[str, Any], dict[str, Any]]:
    """The contact options, and μ and grip (those it sets), of the last placed contact of a
    sole or of a hand."""
    same = [c for c in contacts if is_hand(c["robot_patch"]) == hand and c["surface"] != "ground"]
    if not same:
        return {}, {}
    last = same[-1]
    fixed = {k: last[k] for k in ("mu", "grip") if last.get(k) is not None}
    return {k: copy.deepcopy(last[k]) for k in CONTACT_KEYS if k in last}, fixed


def scene_rules(name: str, seq: Mapping[str, Any], robot: Robot) -> Rules:
    """The robot's default rules narrowed to the scene's surfaces and contact options."""
    info = PLANS[name]
    names = [s["name"] for s in seq["surfaces"]]
    base = default_rules(robot, names, hands=bool(info.hands))
    placed = _placed(seq)
    patches: dict[str, PatchRule] = {}
    for p, rule in base.patches.items():
        hand = is_hand(p)
        options, fixed = _options(placed, hand)
        patches[p] = replace(
            rule,
            surfaces=info.hands if hand else info.soles,
            contact={**dict(rule.contact), **options},
            mu=fixed.get("mu", rule.mu),
            grip=fixed.get("grip", rule.grip),
        )
    return replace(base, patches=patches)
